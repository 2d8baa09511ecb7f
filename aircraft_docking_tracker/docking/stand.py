"""Stand calibration: the stand camera, the lead-in line, the stop marks and the aircraft types (no ROS).

A stand file (``config/stands/*.yaml``, documented there) holds what a surveyor measures once per stand:

* **camera**: ``image_size``, optionally ``focal_px`` (square pixels) and ``principal_point``, and at
  least 4 **apron marks**, each an image point [px] with its stand coordinates [m] on the apron (z = 0).
  The camera's pose comes from the marks (``cv2.solvePnP``, planar, refined to least squares). Without
  ``focal_px`` the focal length is estimated from the marks' ground-plane homography (Zhang's orthogonality
  constraints with square pixels and the principal point known: the image centre unless given) -- the usual
  single-view calibration; a measured focal length is better and is used when given. The marks' residuals
  tell how precisely they were clicked, and :meth:`StandCalibration.survey_covariance` carries that through the
  fit to any apron point: the bias the survey leaves there on every approach.
* **lead_in**: the lead-in line as a polyline [m], in the order the aircraft drives it (entry first).
* **aircraft**: per type, the stop mark (a point [m] on or near the line; the distance to go is measured
  along the line to its foot), the nose height above the apron [m], the tracked template's height
  [m] (ground to fin top: the extent a tracked quadrilateral's vertical sides span, which a turn does
  not shorten), the wingspan [m], and where the nose sits in the tracked template
  (``nose_in_template``: fractions of its width and height); optionally how far behind the nose the
  nose wheel touches the apron (``nose_gear_setback_m``, 0 if left out).

Stand frame: metres, z up; any origin and axes on the apron (the marks fix them). Every check
raises :class:`~aircraft_docking_tracker.config.ConfigError` with the key path in the message.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..config import ConfigError


@dataclass(frozen=True)
class AircraftType:
    """One aircraft type's stop mark and dimensions (stand file ``aircraft.<name>``)."""

    name: str
    stop_m: np.ndarray                 # (2,) stop mark [m]
    nose_height_m: float
    height_m: float                    # tracked template's vertical extent [m]
    wingspan_m: float
    nose_in_template: np.ndarray       # (2,) fractions of the template's width, height
    nose_gear_setback_m: float = 0.0   # how far behind the nose the nose wheel touches the apron [m]

    @property
    def ground_in_template(self) -> float:
        """The apron's row under the nose (the nose wheel's ground contact) as a fraction of the template's height."""
        return float(self.nose_in_template[1] + self.nose_height_m / self.height_m)


class StandCamera:
    """A calibrated pinhole camera: K, R (stand -> camera), centre C [m]; rays and projections."""

    def __init__(self, K: np.ndarray, R: np.ndarray, centre: np.ndarray, image_size):
        self.K, self.R, self.centre = K, R, centre
        self.K_inv = np.linalg.inv(K)
        self.image_size = tuple(int(v) for v in image_size)

    @property
    def focal_px(self) -> float:
        return float(self.K[0, 0])

    def project(self, points) -> np.ndarray:
        """Stand points (N, 3) [m] -> image points (N, 2) [px]."""
        cam = (np.atleast_2d(points) - self.centre) @ self.R.T
        uv = cam @ self.K.T
        return uv[:, :2] / uv[:, 2:3]

    def rays(self, pixels) -> np.ndarray:
        """Directions in the stand frame (N, 3) of image points, scaled to unit depth along the optical axis."""
        pixels = np.atleast_2d(np.asarray(pixels, np.float64))
        cam = np.concatenate([pixels, np.ones((len(pixels), 1))], axis=1) @ self.K_inv.T
        return cam @ self.R

    def depth_on_plane(self, pixels, height_m: float) -> np.ndarray:
        """Depth along the optical axis at which each pixel's ray meets the plane z = ``height_m``
        (NaN where it meets it behind the camera or not at all)."""
        rays = self.rays(pixels)
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = (height_m - self.centre[2]) / rays[:, 2]
        return np.where(depth > 0, depth, np.nan)

    def point_at_depth(self, pixels, depth) -> np.ndarray:
        """Stand points (N, 3) on each pixel's ray at the given optical-axis depth."""
        return self.centre + self.rays(pixels) * np.reshape(depth, (-1, 1))

    def on_plane(self, pixels, height_m: float = 0.0) -> np.ndarray:
        """Stand points (N, 3) where each pixel's ray meets the plane z = ``height_m`` (the apron by default; NaN
        where it does not, in front of the camera)."""
        return self.point_at_depth(pixels, self.depth_on_plane(pixels, height_m))


@dataclass(frozen=True)
class StandCalibration:
    """A stand: its camera, its lead-in line and its aircraft types."""

    name: str
    camera: StandCamera
    lead_in: np.ndarray                # (M, 2) [m], entry first
    aircraft: dict                     # name -> AircraftType
    marks: ApronMarks                  # the surveyed marks the camera was fitted to

    @functools.cached_property
    def reprojection_px(self) -> float:
        """RMS reprojection error of the apron marks [px]."""
        return self.marks.reprojection_px(self.camera)

    @property
    def click_sigma_px(self) -> float:
        """The marks' clicking error [px, 1 sigma] that their residuals imply (NaN: too few marks to tell)."""
        return self.marks.click_sigma_px(self.reprojection_px)

    def survey_covariance(self, point) -> np.ndarray:
        """The 2x2 covariance [m^2] the survey leaves on the apron ``point`` [m] (:meth:`ApronMarks.covariance` at
        :attr:`click_sigma_px`, about this stand's camera); NaN if it cannot be told."""
        sigma = self.click_sigma_px
        if not np.isfinite(sigma):
            return np.full((2, 2), np.nan)
        try:
            return self.marks.covariance(point, sigma, self.camera)
        except ConfigError:           # marks on the edge of fitting at all: moved a twentieth of a pixel, they don't
            return np.full((2, 2), np.nan)

    def aircraft_type(self, name: str) -> AircraftType:
        if name not in self.aircraft:
            raise ConfigError(f"stand {self.name!r} has no aircraft type {name!r} (has {sorted(self.aircraft)})",
                              ("aircraft_type",))
        return self.aircraft[name]


def focal_from_homography(H: np.ndarray, principal_point) -> float:
    """Focal length [px] from a plane-to-image homography, square pixels and a known principal point
    (Zhang 2000: the plane's axes r1, r2 are orthogonal and of equal length). NaN when the two
    constraints cannot fix it (a camera looking straight along the plane's axes and square onto it)."""
    T = np.array([[1.0, 0.0, -principal_point[0]], [0.0, 1.0, -principal_point[1]], [0.0, 0.0, 1.0]])
    h = T @ H
    h1, h2 = h[:, 0], h[:, 1]
    # h1' W h2 = 0 and h1' W h1 = h2' W h2 with W = diag(1/f^2, 1/f^2, 1): linear in u = 1/f^2
    a = np.array([h1[0] * h2[0] + h1[1] * h2[1], h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2])
    b = np.array([-h1[2] * h2[2], h2[2] ** 2 - h1[2] ** 2])
    denominator = float(a @ a)
    if denominator <= 0:
        return float("nan")
    u = float(a @ b) / denominator
    return 1.0 / np.sqrt(u) if u > 0 else float("nan")


def _points(value, key: str, count: int | None = None, dims: int = 2) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{key}: {value!r} is not a list of numbers", (key,)) from None
    if array.ndim == 1:
        array = array.reshape(1, -1) if count == 1 else array
    if array.ndim != 2 or array.shape[1] != dims or (count is not None and len(array) != count):
        want = f"{count} point(s)" if count else "a list of points"
        raise ConfigError(f"{key}: needs {want} of {dims} numbers, got {value!r}", (key,))
    if not np.isfinite(array).all():
        raise ConfigError(f"{key}: has a value that is not a finite number", (key,))
    return array


def _positive(table: dict, key: str, path: str) -> float:
    value = table.get(key)
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value) or value <= 0:
        raise ConfigError(f"{path}.{key}: needs a positive number, got {value!r}", (f"{path}.{key}",))
    return float(value)


@dataclass(frozen=True)
class ApronMarks:
    """The surveyed apron marks and what the camera's fit takes from the stand file besides them."""

    ground: np.ndarray                 # (N, 2) stand coordinates [m], on the apron
    image: np.ndarray                  # (N, 2) where they were clicked in the image [px]
    image_size: np.ndarray             # (2,) [px]
    principal_point: np.ndarray        # (2,) [px]
    focal_px: float                    # the measured focal length [px]; 0: estimated from the marks

    def camera(self, image: np.ndarray | None = None) -> StandCamera:
        """The camera that sees the marks at ``image`` (default: where they were clicked): the focal length given,
        or from their ground-plane homography, and the pose by ``cv2.solvePnP`` (planar, IPPE), refined to the
        least-squares reprojection error."""
        image = self.image if image is None else image
        H, _ = cv2.findHomography(self.ground, image, 0)
        if H is None:
            raise ConfigError("camera.points: the apron marks lie on one line; they must span the apron",
                              ("camera.points",))
        focal = self.focal_px
        if focal == 0:
            focal = focal_from_homography(H, self.principal_point)
            if not np.isfinite(focal):
                raise ConfigError("camera.focal_px: cannot be estimated from these marks (the camera looks square "
                                  "onto the stand axes); give the measured focal length", ("camera.focal_px",))
        K = np.array([[focal, 0.0, self.principal_point[0]], [0.0, focal, self.principal_point[1]], [0.0, 0.0, 1.0]])
        ok, rvec, tvec = cv2.solvePnP(self.on_apron, image, K, None, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            raise ConfigError("camera.points: no camera pose fits these apron marks", ("camera.points",))
        # IPPE solves from the homography; Levenberg-Marquardt then takes it to the least-squares pose, whose
        # residuals tell the clicks' error (IPPE's read it 10-25 % high; the stop mark's place moves by < 0.01 m)
        rvec, tvec = cv2.solvePnPRefineLM(self.on_apron, image, K, None, rvec, tvec)
        R = cv2.Rodrigues(rvec)[0]
        centre = (-R.T @ tvec).ravel()
        if centre[2] <= 0:           # IPPE's planar ambiguity: the mirror pose below the apron
            raise ConfigError("camera.points: the pose found puts the camera below the apron; check the marks",
                              ("camera.points",))
        return StandCamera(K, R, centre, self.image_size)

    @property
    def on_apron(self) -> np.ndarray:
        """The marks as stand points (N, 3) [m], z = 0."""
        return np.c_[self.ground, np.zeros(len(self.ground))]

    def reprojection_px(self, camera: StandCamera) -> float:
        """RMS distance [px] between where ``camera`` sees the marks and where they were clicked."""
        return float(np.sqrt(np.mean(np.sum((camera.project(self.on_apron) - self.image) ** 2, axis=1))))

    def click_sigma_px(self, reprojection_px: float) -> float:
        """The clicking error [px, 1 sigma per coordinate] the marks' residuals imply: their RMS distance times
        sqrt(N / (2N - p)), p = 6 pose parameters (7 with the focal length estimated: the fit takes p of the 2N
        coordinates' freedom); NaN with too few marks to tell (2N <= p)."""
        parameters = 6 if self.focal_px else 7
        n = len(self.ground)
        return float(reprojection_px * np.sqrt(n / (2 * n - parameters))) if 2 * n > parameters else float("nan")

    def covariance(self, point, sigma_px: float, camera: StandCamera | None = None,
                   step_px: float = 0.05) -> np.ndarray:
        """The 2x2 covariance [m^2] of where the fitted camera puts the apron ``point`` [m] (x, y), from clicks
        each ``sigma_px`` off (independent): Sigma = sigma^2 J^T J, J the derivative, by each of the marks' 2N image
        coordinates, of the apron point that the camera fitted to the moved marks sees at ``point``'s pixel
        (central differences of ``step_px``; first-order propagation through the fit). It is the bias a survey
        leaves on every figure measured near ``point``: no smoothing removes it. ``camera``: the marks' own fit,
        if already made."""
        pixel = (camera or self.camera()).project([[float(point[0]), float(point[1]), 0.0]])

        def apron_at(image: np.ndarray) -> np.ndarray:
            return self.camera(image).on_plane(pixel)[0, :2]

        jacobian = np.empty((self.image.size, 2))
        for k in range(self.image.size):
            step = np.zeros(self.image.size)
            step[k] = step_px
            step = step.reshape(self.image.shape)
            jacobian[k] = (apron_at(self.image + step) - apron_at(self.image - step)) / (2 * step_px)
        return sigma_px ** 2 * jacobian.T @ jacobian


def calibrate_camera(table: dict) -> tuple[StandCamera, ApronMarks]:
    """The ``camera`` section -> (camera, the marks it was fitted to)."""
    if not isinstance(table, dict):
        raise ConfigError("camera: needs a mapping (image_size, points, optional focal_px, principal_point)",
                          ("camera",))
    size = _points(table.get("image_size"), "camera.image_size", 1)[0]
    if (size < 1).any():
        raise ConfigError(f"camera.image_size: {size.tolist()} is not a size", ("camera.image_size",))
    points = table.get("points")
    if not isinstance(points, list) or len(points) < 4:
        raise ConfigError("camera.points: needs at least 4 apron marks {image: [u, v], stand: [x, y]}",
                          ("camera.points",))
    image = np.array([_points(m.get("image") if isinstance(m, dict) else None, f"camera.points[{i}].image", 1)[0]
                      for i, m in enumerate(points)])
    ground = np.array([_points(m.get("stand"), f"camera.points[{i}].stand", 1)[0] for i, m in enumerate(points)])
    principal = (_points(table["principal_point"], "camera.principal_point", 1)[0]
                 if table.get("principal_point") is not None else size / 2.0)
    spread = np.linalg.svd(ground - ground.mean(axis=0), compute_uv=False)
    if spread[1] < 1e-3 * max(spread[0], 1e-9):
        raise ConfigError("camera.points: the apron marks lie on one line; they must span the apron",
                          ("camera.points",))
    focal = table.get("focal_px") or 0.0
    if not isinstance(focal, (int, float)) or isinstance(focal, bool) or not np.isfinite(focal) or focal < 0:
        raise ConfigError(f"camera.focal_px: needs a positive number (or 0: estimate it), got {focal!r}",
                          ("camera.focal_px",))
    marks = ApronMarks(ground, image, size, principal, float(focal))
    return marks.camera(), marks


def parse_stand(data: dict, name: str = "stand") -> StandCalibration:
    """A stand file's mapping -> :class:`StandCalibration` (every field checked)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{name}: a stand file holds a mapping (camera, lead_in, aircraft)", ())
    camera, marks = calibrate_camera(data.get("camera"))
    lead_in = _points(data.get("lead_in"), "lead_in")
    if len(lead_in) < 2 or np.linalg.norm(np.diff(lead_in, axis=0), axis=1).min() <= 0:
        raise ConfigError("lead_in: needs at least 2 distinct points [m], entry first", ("lead_in",))
    types = data.get("aircraft")
    if not isinstance(types, dict) or not types:
        raise ConfigError("aircraft: needs at least one aircraft type", ("aircraft",))
    aircraft = {}
    for type_name, entry in types.items():
        path = f"aircraft.{type_name}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{path}: needs a mapping (stop_m, nose_height_m, height_m, wingspan_m, "
                              "nose_in_template)", (path,))
        nose = _points(entry.get("nose_in_template"), f"{path}.nose_in_template", 1)[0]
        if ((nose < 0) | (nose > 1)).any():
            raise ConfigError(f"{path}.nose_in_template: fractions in [0, 1], got {nose.tolist()}",
                              (f"{path}.nose_in_template",))
        setback = entry.get("nose_gear_setback_m", 0.0)
        if isinstance(setback, bool) or not isinstance(setback, (int, float)) or not 0 <= setback < 100:
            raise ConfigError(f"{path}.nose_gear_setback_m: a distance in [0, 100) m, got {setback!r}",
                              (f"{path}.nose_gear_setback_m",))
        aircraft[str(type_name)] = AircraftType(
            str(type_name), _points(entry.get("stop_m"), f"{path}.stop_m", 1)[0],
            _positive(entry, "nose_height_m", path), _positive(entry, "height_m", path),
            _positive(entry, "wingspan_m", path), nose, float(setback))
    return StandCalibration(str(data.get("stand", name)), camera, lead_in, aircraft, marks)


def load_stand(path: str | Path) -> StandCalibration:
    """Read and check a stand file; a relative name is looked up in the package's ``config/stands``."""
    import yaml  # noqa: PLC0415

    from ..config import package_config_dir  # noqa: PLC0415

    path = Path(path)
    if not path.is_file() and not path.is_absolute() and (package_config_dir() / "stands" / path).is_file():
        path = package_config_dir() / "stands" / path
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError(f"stand file {path}: {exc.strerror or exc}", ("stand_file",)) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"stand file {path}: not YAML ({exc})", ("stand_file",)) from None
    try:
        return parse_stand(data, path.stem)
    except ConfigError as exc:
        raise ConfigError(f"stand file {path}: {exc}", ("stand_file",)) from None


STAND_FILE_HEADER = """\
# Stand calibration (aircraft_docking_tracker.docking.stand; how to make one: README, "Calibrating a stand").
# Stand frame: metres on the apron, z up; any origin and axes (the apron marks below fix them).
#
# camera:
#   image_size: [width, height] of the camera's images [px]
#   focal_px: focal length [px, square pixels] from the lens' calibration; 0: estimated from the marks
#   principal_point: [cx, cy] [px]; leave out: the image centre
#   points: >= 4 apron marks not all on one line (paint corners, stop bar ends, slab-joint crossings):
#     image: [u, v] where the mark is in the camera's image [px]; stand: [x, y] its surveyed position [m]
# lead_in: the painted lead-in line as a polyline [m], in the order the aircraft drives it (entry first);
#   let it run on a few metres past the last stop mark, so that an overshoot is measured along it
# aircraft: per type (the guidance's aircraft_type parameter picks one)
#   stop_m: [x, y] the type's stop mark [m]; the distance to go is measured along the line to its foot
#   nose_height_m: the nose's height above the apron [m] (where the tracker's nose point is)
#   height_m: the tracked template's height, ground to fin top [m] (range from the apparent size)
#   wingspan_m: wingspan [m]
#   nose_in_template: [u, v] where the nose sits in the tracked template, fractions of its width and height
#   nose_gear_setback_m: how far behind the nose the nose wheel touches the apron [m] (optional, 0; the
#     guidance measures the wheel's ground contact near the stop and puts the nose this far ahead of it)
"""


def stand_file_text(data: dict) -> str:
    """A stand mapping (as :func:`parse_stand` reads it) as a documented YAML stand file; checked first."""
    import yaml  # noqa: PLC0415

    parse_stand(data)
    body = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110)
    return STAND_FILE_HEADER + body
