# Source with the venv folder as argument: sets, once and in a fixed order, the environment that
# the ROS 2 Jazzy wheels from PyPI need, so that their bootstrapper does not re-execute Python.
# Used by every command that `make` runs, and appended to .venv/bin/activate by `make setup`.
_adt_venv="$(cd "${1:-.venv}" && pwd)"
_adt_site="$(ls -d "$_adt_venv"/lib/python3*/site-packages 2>/dev/null | head -n 1)"
_adt_ld="$_adt_venv/lib"
for _adt_d in "$_adt_site"/ros_*.libs; do
  [ -d "$_adt_d" ] && _adt_ld="$_adt_ld:$_adt_d"
done
case ":${LD_LIBRARY_PATH:-}:" in
  *":$_adt_venv/lib:"*) ;;
  *) export LD_LIBRARY_PATH="$_adt_ld${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" ;;
esac
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$_adt_venv:"*) ;;
  *) export AMENT_PREFIX_PATH="$_adt_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
export ROS_LOG_DIR="${ROS_LOG_DIR:-${TMPDIR:-/tmp}/aircraft_docking_tracker-ros-log}"
# One host by default (LOCALHOST). ADT_MULTIHOST=1: nodes on several hosts (README "Several hosts"):
# discovery over the subnet and config/fastdds_multihost.xml (shared memory + UDPv4, large socket buffers).
if [ "${ADT_MULTIHOST:-0}" = "1" ]; then
  export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-SUBNET}"
  _adt_profile=fastdds_multihost.xml
else
  export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
  _adt_profile=fastdds_large_images.xml
fi
# Shared-memory segments large enough for camera images (config/fastdds_large_images.xml explains).
if [ -z "${FASTDDS_DEFAULT_PROFILES_FILE:-}" ] && [ -z "${FASTRTPS_DEFAULT_PROFILES_FILE:-}" ]; then
  _adt_xml="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")/.." && pwd)/config/$_adt_profile"
  if [ -f "$_adt_xml" ]; then
    export FASTDDS_DEFAULT_PROFILES_FILE="$_adt_xml" FASTRTPS_DEFAULT_PROFILES_FILE="$_adt_xml"
  fi
  unset _adt_xml
fi
export MPLBACKEND="${MPLBACKEND:-Agg}"
export PYTHONUNBUFFERED=1
case ":$PATH:" in
  *":$_adt_venv/bin:"*) ;;
  *) export PATH="$_adt_venv/bin:$PATH" ;;
esac
unset _adt_venv _adt_site _adt_ld _adt_d _adt_profile
