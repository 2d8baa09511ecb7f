"""Several "hosts" on one Linux machine: network namespaces joined by a bridge, for multi-host tests.

    with VirtualNetwork() as net:                    # needs root and iproute2 (`apt-get install iproute2`)
        cam, compute = net.add_host("cam"), net.add_host("compute")
        player = NodeProcess("mcap_play", args=[...], prefix=cam.prefix, env=net.ros_env())
        net.link(cam, up=False)                      # unplug the camera host's cable
        net.impair(compute, loss_pct=1.0)            # lose 1 % of the packets the compute host receives

Each host is a network namespace with one interface ``eth0`` (10.231.<n>.<k>/24, nothing outside
the namespaces is ever addressed) plugged into a bridge that lives in a namespace of its own, so the
machine's own interfaces, routes and firewall are never touched. Every process a host runs also
gets that host's own ``/dev/shm`` (a directory bind-mounted over it): Fast DDS cannot take a
shared-memory short cut between hosts, and all their traffic crosses the emulated network, as it
would between machines. The network removes everything it made on :meth:`close` (a ``with`` block, a
``finally``, and an ``atexit`` hook for the last resort); a network left behind by a run that was
killed is removed by the next one (names carry the creating process's id).

Faults: :meth:`link` takes ``eth0`` down and up (`ip link set`); :meth:`impair` adds packet loss and
delay with ``tc netem`` where the kernel has ``sch_netem``, else loss alone with an nftables rule
(``numgen random``; `apt-get install nftables`), else raises :class:`NetworkUnavailable`.
"""
from __future__ import annotations

import atexit
import itertools
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

NAME_PREFIX = "adtnet"
_NAME = re.compile(rf"^{NAME_PREFIX}-(\d+)-\d+-")
_counter = itertools.count(1)


class NetworkUnavailable(RuntimeError):
    """This machine cannot build the emulated network, or not this fault (the reason says why)."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=30)


def _netns_names() -> list[str]:
    out = _ip("netns", "list", check=False).stdout
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _kill_namespace_processes(ns: str) -> None:
    """SIGKILL whatever still runs in ``ns`` (only processes this harness started live there)."""
    for _ in range(3):
        pids = [int(p) for p in _ip("netns", "pids", ns, check=False).stdout.split() if p.isdigit()]
        if not pids:
            return
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.2)


def _delete_namespace(ns: str) -> None:
    _kill_namespace_processes(ns)
    _ip("netns", "delete", ns, check=False)


def remove_stale_networks() -> list[str]:
    """Delete namespaces left by a run of this harness whose process is gone (it was killed)."""
    removed = []
    for ns in _netns_names():
        match = _NAME.match(ns)
        if match and not _pid_alive(int(match.group(1))):
            _delete_namespace(ns)
            removed.append(ns)
    return removed


def unavailable_reason() -> str | None:
    """Why this machine cannot build a :class:`VirtualNetwork`, or None when it can."""
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed: apt-get install iproute2"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN)"
    probe = f"{NAME_PREFIX}-{os.getpid()}-0-probe"
    result = _ip("netns", "add", probe, check=False)
    if result.returncode != 0:
        return f"cannot create a network namespace: {result.stderr.strip()}"
    try:
        veth = _ip("-n", probe, "link", "add", "p0", "type", "veth", "peer", "name", "p1", check=False)
        if veth.returncode != 0:
            return f"cannot create a veth pair: {veth.stderr.strip()}"
        bridge = _ip("-n", probe, "link", "add", "b0", "type", "bridge", check=False)
        if bridge.returncode != 0:
            return f"cannot create a bridge: {bridge.stderr.strip()}"
    finally:
        _ip("netns", "delete", probe, check=False)
    return None


@dataclass
class Host:
    """One emulated machine: a namespace, an address, a private /dev/shm."""

    name: str
    namespace: str
    address: str
    shm_dir: Path
    switch_port: str
    impaired: list[str] = field(default_factory=list)

    @property
    def prefix(self) -> list[str]:
        """Command prefix that runs the rest of a command line on this host (``NodeProcess.prefix``)."""
        script = 'mount --bind "$ADT_HOST_SHM" /dev/shm && exec "$@"'
        return ["ip", "netns", "exec", self.namespace, "env", f"ADT_HOST_SHM={self.shm_dir}",
                "sh", "-c", script, "sh"]

    def run(self, *command: str, check: bool = True, timeout: float = 30) -> subprocess.CompletedProcess:
        """Run a short command on this host and wait for it."""
        return subprocess.run(["ip", "netns", "exec", self.namespace, *command], capture_output=True, text=True,
                              check=check, timeout=timeout)


class VirtualNetwork:
    """Hosts (network namespaces) on one emulated Ethernet segment, removed again on :meth:`close`."""

    def __init__(self, subnet: int | None = None, multicast: bool = True):
        reason = unavailable_reason()
        if reason:
            raise NetworkUnavailable(reason)
        remove_stale_networks()
        self.tag = f"{NAME_PREFIX}-{os.getpid()}-{next(_counter)}"
        # 10.231.<subnet>.0/24: a different subnet per network object, so parallel networks never meet
        self.subnet = subnet if subnet is not None else (os.getpid() * 7 + next(_counter)) % 250 + 1
        self.multicast = multicast  # False: the switch drops multicast (discovery needs peers)
        self.hosts: dict[str, Host] = {}
        self._namespaces: list[str] = []
        self._closed = False
        self._workdir = Path(tempfile.mkdtemp(prefix=f"{self.tag}-"))
        atexit.register(self.close)
        try:
            self.switch = self._add_namespace("sw")
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self.switch, "link", "set", "br0", "up")
            if not multicast:
                self._block_multicast()
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------ building
    def _block_multicast(self) -> None:
        """The switch forwards no IPv4 multicast between hosts (an nftables bridge rule)."""
        if shutil.which("nft") is None:
            raise NetworkUnavailable("a network without multicast needs nftables (apt-get install nftables)")
        rules = ("table bridge adt_no_multicast { chain forward { type filter hook forward priority 0; "
                 "ip daddr 224.0.0.0/4 drop; }; }")
        result = subprocess.run(["ip", "netns", "exec", self.switch, "nft", "-f", "-"], input=rules,
                                capture_output=True, text=True, timeout=30)
        if result.returncode != 0:
            raise NetworkUnavailable(f"cannot block multicast on the switch: {result.stderr.strip()}")

    def _add_namespace(self, suffix: str) -> str:
        ns = f"{self.tag}-{suffix}"
        _ip("netns", "add", ns)
        self._namespaces.append(ns)
        _ip("-n", ns, "link", "set", "lo", "up")
        return ns

    def add_host(self, name: str) -> Host:
        if name in self.hosts or not re.fullmatch(r"[a-z][a-z0-9]{0,9}", name):
            raise ValueError(f"host name {name!r}: new, lower-case letters and digits, at most 10")
        index = len(self.hosts) + 1
        ns = self._add_namespace(name)
        port = f"p{index}"
        _ip("-n", self.switch, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", ns)
        _ip("-n", self.switch, "link", "set", port, "master", "br0", "up")
        address = f"10.231.{self.subnet}.{index}"
        _ip("-n", ns, "addr", "add", f"{address}/24", "dev", "eth0")
        _ip("-n", ns, "link", "set", "eth0", "up")
        # DDS discovery multicast (239.255.0.1) leaves through eth0, the only route (without
        # multicast, the switch drops it)
        _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
        shm = self._workdir / f"shm-{name}"
        shm.mkdir(mode=0o1777)
        host = Host(name, ns, address, shm, port)
        self.hosts[name] = host
        return host

    def ros_env(self, profile: str | Path | None = None, peers: list[Host] | None = None) -> dict[str, str]:
        """Environment for ROS 2 processes on these hosts: discovery over the subnet, Fast DDS profile.

        ``profile`` defaults to the package's config/fastdds_multihost.xml. ``peers``: use unicast
        discovery to these hosts (``ROS_STATIC_PEERS``) as on a network without multicast.
        """
        if profile is None:
            from .config import package_config_dir  # noqa: PLC0415

            profile = package_config_dir() / "fastdds_multihost.xml"
        env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
               "FASTDDS_DEFAULT_PROFILES_FILE": str(profile), "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)}
        if peers:
            env["ROS_STATIC_PEERS"] = ";".join(h.address for h in peers)
        return env

    # ------------------------------------------------------------------ faults
    def link(self, host: Host, up: bool) -> None:
        """Plug (``up``) or unplug the host's cable: its ``eth0`` goes up or down."""
        _ip("-n", host.namespace, "link", "set", "eth0", "up" if up else "down")

    def impair(self, host: Host, loss_pct: float = 0.0, delay_ms: float = 0.0) -> str:
        """Lose ``loss_pct`` % of the packets ``host`` receives and delay what it sends by ``delay_ms``.

        Returns the mechanism used ("netem" or "nftables"); raises NetworkUnavailable when neither
        can do what was asked (delay needs ``sch_netem`` in the kernel).
        """
        self.clear_impairment(host)
        if loss_pct <= 0 and delay_ms <= 0:
            return "none"
        netem = ["tc", "qdisc", "add", "dev", "eth0", "root", "netem"]
        if delay_ms > 0:
            netem += ["delay", f"{delay_ms}ms"]
        if loss_pct > 0:
            netem += ["loss", f"{loss_pct}%"]
        result = host.run(*netem, check=False) if shutil.which("tc") else None
        if result is not None and result.returncode == 0:
            host.impaired.append("netem")
            return "netem"
        netem_error = result.stderr.strip() if result is not None else "tc is not installed (apt-get install iproute2)"
        if delay_ms > 0:
            raise NetworkUnavailable(f"delay needs tc netem: {netem_error}")
        if shutil.which("nft") is None:
            raise NetworkUnavailable(f"packet loss needs tc netem ({netem_error}) or nftables (apt-get install nftables)")
        # per packet (IP fragment) on the wire, before reassembly: netdev ingress of eth0
        threshold = max(1, min(1_000_000, round(loss_pct * 10_000)))
        rules = (f"table netdev adt_loss {{ chain ingress {{ type filter hook ingress device \"eth0\" priority 0; "
                 f"numgen random mod 1000000 < {threshold} counter drop; }}; }}")
        result = subprocess.run(["ip", "netns", "exec", host.namespace, "nft", "-f", "-"], input=rules,
                                capture_output=True, text=True, timeout=30)
        if result.returncode != 0:
            raise NetworkUnavailable(f"packet loss: tc netem failed ({netem_error}) and nftables too "
                                     f"({result.stderr.strip()})")
        host.impaired.append("nftables")
        return "nftables"

    def dropped_packets(self, host: Host) -> int | None:
        """Packets dropped so far by an nftables loss rule on ``host`` (None without one)."""
        if "nftables" not in host.impaired:
            return None
        out = host.run("nft", "list", "table", "netdev", "adt_loss", check=False).stdout
        match = re.search(r"counter packets (\d+)", out)
        return int(match.group(1)) if match else None

    def clear_impairment(self, host: Host) -> None:
        if "netem" in host.impaired:
            host.run("tc", "qdisc", "del", "dev", "eth0", "root", check=False)
        if "nftables" in host.impaired:
            host.run("nft", "delete", "table", "netdev", "adt_loss", check=False)
        host.impaired.clear()

    # ------------------------------------------------------------------ removal
    def close(self) -> None:
        """Kill what still runs on the hosts and delete every namespace and directory made."""
        if self._closed:
            return
        self._closed = True
        for ns in reversed(self._namespaces):
            _delete_namespace(ns)
        shutil.rmtree(self._workdir, ignore_errors=True)
        try:
            atexit.unregister(self.close)
        except Exception:  # pragma: no cover - interpreter shutting down
            pass

    def __enter__(self) -> "VirtualNetwork":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
