"""The nose wheel's ground contact, measured in the image on the aircraft's symmetry axis (no ROS).

Near the stop the docking aircraft is large in the stand camera's image (150-270 px tall in the
synthetic stands), but the tracked quadrilateral carries whole-aircraft errors there: a few percent
of size (a range error of metres at 40-60 m) and tens of pixels sideways when a jet bridge hides a
wing. What a pilot is guided by is one point, the nose, and seen nose-on two things in the image
pin it down without the template:

1. **The symmetry axis.** Seen nose-on an aircraft is mirror-symmetric about the vertical plane
   through its fuselage. In an upright strip resampled about the tracked nose (1 px per image pixel,
   its columns along the apron's vertical as the calibrated camera sees it there: the tracked
   template's own vertical is only as good as the tracker's rotation, measured up to 20 degrees off
   late in an approach, and about a tilted line a fuselage is not symmetric but an engine's round
   cowl still is), the axis is the column ``c`` whose left
   neighbourhood best matches its mirrored right one over the nose's rows: the normalised
   correlation of ``strip[rows, c-K:c]`` with ``strip[rows, c+1:c+K+1]`` flipped, searched within
   ``search`` template heights of the tracked nose (every other column on every other row first,
   then every column and row about its three best peaks), refined to a sub-pixel by a parabola through the best three
   scores. ``K`` is ``window`` template heights (about the fuselage's half-width). An engine's round cowl can be
   as symmetric as the nose: with ``axes`` > 1 the best column about each of the first few peaks is a candidate,
   most symmetric first, and the first with a tyre's step under it (``axis_contrast``, step 2) is the axis.
2. **The ground contact** on that axis: the nose wheel (a dark tyre) meets the lit apron in a step
   of the column's grey profile (averaged over ``band`` template heights either side of the axis),
   dark above, bright below. It is the lowest row whose step is a peak of at least ``lowest_step`` of the largest
   step within ``contact_window`` template heights of where the template puts it (the nose's row plus the type's nose
   height: a template a fifth too small puts it a window too high, where a strong step above the tyre is the
   largest; under the tyre there is only apron; ``lowest_step`` 0: the largest step), the step being the
   darker of two apron bands below the row less the tyre's rows above it (:func:`tyre_steps`: a
   painted stop bar under the axis has apron above it and is bright in its first band only, and was
   taken for the contact when the step was the profile's derivative alone); the edge is then placed
   to a sub-pixel at the derivative's peak from an apron band above that row to the row after it, by a parabola
   (:func:`ground_contact`: a slab joint right under the tyre otherwise moved it under the joint). The contact is
   on the apron (z = 0), so its range comes
   from the calibrated ground plane with the camera's whole height above it, where the nose's own
   row (z = nose height) has only the camera's height above the nose: a pixel there is
   Z^2 / (f h_camera) metres of range instead of Z^2 / (f (h_camera - h_nose)).

A measurement is refused (the caller falls back to the tracked quadrilateral) when the template is
under ``min_height_px`` tall, when the best symmetry score is under ``min_symmetry``, when the step
is under ``min_contrast`` grey levels, or when the strip leaves the image.
"""
from __future__ import annotations

import cv2
import numpy as np

#: One frame's measurement, in image pixels; NaN where nothing was measured.
NOSE_GEAR_DTYPE = np.dtype([("axis_x", "<f8"), ("axis_y", "<f8"), ("ground_x", "<f8"), ("ground_y", "<f8"),
                            ("symmetry", "<f8"), ("contrast", "<f8")])


COARSE_PEAKS = 3   # the coarse symmetry search's peaks refined at full resolution
TYRE = 0.03        # the tyre's rows above the contact that are compared [template heights]
APRON = 0.015      # each of the two apron bands below it [template heights]


def tyre_steps(profile: np.ndarray, above: int, below: int) -> np.ndarray:
    """Per row r of a grey profile (going down), the step from the tyre to the apron between r and r + 1: the
    darker of the two bands of ``below`` rows under it, less the mean of the ``above`` rows down to r. A painted
    line under the axis is bright only in its first band, so it is no step; a tyre on the apron is both.
    -inf where the bands leave the profile."""
    sums = np.concatenate([[0.0], np.cumsum(profile, dtype=np.float64)])
    n = len(profile)
    r = np.arange(n)
    ok = (r - above + 1 >= 0) & (r + 2 * below < n)
    rc = np.clip(r, above - 1, n - 1 - 2 * below)
    tyre = (sums[rc + 1] - sums[rc + 1 - above]) / above
    near = (sums[rc + 1 + below] - sums[rc + 1]) / below
    far = (sums[rc + 1 + 2 * below] - sums[rc + 1 + below]) / below
    return np.where(ok, np.minimum(near, far) - tyre, -np.inf)


def _parabola_peak(scores: np.ndarray, i: int) -> float:
    """Sub-sample offset of the peak at ``i`` from a parabola through it and its neighbours."""
    if 0 < i < len(scores) - 1:
        curvature = scores[i - 1] - 2.0 * scores[i] + scores[i + 1]
        if curvature < 0:
            return float(np.clip(0.5 * (scores[i - 1] - scores[i + 1]) / curvature, -0.5, 0.5))
    return 0.0


def mirror_scores(rows: np.ndarray, columns: np.ndarray, half_width: int) -> np.ndarray:
    """Normalised correlation of each candidate column's left neighbourhood (``half_width`` columns) with its mirrored
    right one, over ``rows``; every candidate at once (the columns need ``half_width`` of room either side)."""
    windows = np.lib.stride_tricks.sliding_window_view(rows, half_width, axis=1)     # (rows, start, k)
    left = windows[:, columns - half_width]                                          # columns c-K .. c-1
    right = windows[:, columns + 1, ::-1]                                            # c+K .. c+1, mirrored
    left = left - left.mean(axis=(0, 2), keepdims=True)
    right = right - right.mean(axis=(0, 2), keepdims=True)
    cross = np.einsum("rck,rck->c", left, right)
    norm = np.sqrt(np.einsum("rck,rck->c", left, left) * np.einsum("rck,rck->c", right, right))
    return np.where(norm > 0, cross / np.where(norm > 0, norm, 1.0), -1.0)


def local_peaks(values: np.ndarray) -> np.ndarray:
    """Indices, in order, of the entries of a 1-D array at least as large as both neighbours (the ends compared with
    their one neighbour)."""
    padded = np.concatenate([[-np.inf], values, [-np.inf]])
    return np.flatnonzero((values >= padded[:-2]) & (values >= padded[2:]))


def template_vertical(quad: np.ndarray) -> np.ndarray:
    """The mean of the tracked template's two vertical sides (TL->BL, TR->BR) in the image [px]."""
    quad = np.asarray(quad, np.float64)
    return 0.5 * ((quad[3] - quad[0]) + (quad[2] - quad[1]))


def template_height(quad: np.ndarray) -> float:
    """The tracked template's height in the image [px]: the length of :func:`template_vertical`."""
    return float(np.linalg.norm(template_vertical(quad)))


def measure_nose_gear(image: np.ndarray, quad: np.ndarray, nose_in_template, ground_in_template: float,
                      down=None, *,
                      min_height_px: float = 80.0, search: float = 0.5, window: float = 0.12, band: float = 0.02,
                      min_symmetry: float = 0.5, min_contrast: float = 12.0, axes: int = 1,
                      axis_contrast: float = 30.0, contact_window: float | None = None,
                      lowest_step: float = 0.0) -> np.ndarray:
    """One :data:`NOSE_GEAR_DTYPE` row: the symmetry axis at the nose's row and the nose wheel's ground
    contact (image pixels) of the aircraft tracked as ``quad`` (TL, TR, BR, BL) in ``image`` (grey, or BGR: only the
    strip's pixels are turned grey).
    ``ground_in_template`` is the contact's fraction of the template's height; ``down`` the image direction of
    the apron's vertical at the nose (from the calibrated camera; None: the template's own vertical, which
    a tracker's rotation error tilts); ``axes``: how many symmetric axes (the best column about each of the coarse
    search's peaks, at least ``min_symmetry``, most symmetric first) are looked at: the first whose step reaches
    ``axis_contrast`` is taken, the most symmetric if none does (1: the most symmetric axis alone);
    ``contact_window``: the ground contact's search either side of where the template puts it [template heights]
    (None: ``window``, the symmetry's half-width); the other
    arguments are the module docstring's (``guidance.gear_*``). NaN where refused."""
    row = np.full(1, np.nan, NOSE_GEAR_DTYPE)
    quad = np.asarray(quad, np.float64)
    colour = image.ndim == 3 and image.shape[2] == 3
    if not (image.ndim == 2 or colour) or not np.isfinite(quad).all():
        return row
    sides = template_vertical(quad)
    height = float(np.linalg.norm(sides))
    if min_height_px <= 0 or height < min_height_px:
        return row
    down = np.asarray(down if down is not None else sides, np.float64)
    down = down / np.linalg.norm(down)
    right = np.array([down[1], -down[0]])
    u, v = nose_in_template
    nose = quad[0] + u * (quad[1] - quad[0]) + v * (quad[3] - quad[0])
    half_window = max(2, int(round(window * height)))
    reach = max(1, int(round(search * height)))
    half = reach + half_window + 1
    top = half_window + 1                                   # strip rows above the nose's row
    half_contact = half_window if contact_window is None else max(2, int(round(contact_window * height)))
    bottom = int(np.ceil((ground_in_template - v) * height)) + half_contact + int(np.ceil(2 * APRON * height)) + 6
    # strip (a, b) -> image: nose + (a - half) right + (b - top) down
    to_image = np.array([[right[0], down[0], nose[0] - half * right[0] - top * down[0]],
                         [right[1], down[1], nose[1] - half * right[1] - top * down[1]]])
    corners = np.array([[0, 0, 1], [2 * half, 0, 1], [0, top + bottom, 1], [2 * half, top + bottom, 1]]) @ to_image.T
    h_img, w_img = image.shape[:2]
    if (corners < 0).any() or (corners[:, 0] > w_img - 1).any() or (corners[:, 1] > h_img - 1).any():
        return row
    # only the pixels under the strip (and the next ones the bilinear samples reach) are turned grey and warped:
    # the same strip to the bit as from the whole grey frame, a fraction of a 640x480 frame's conversion
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)).astype(int), np.ceil(corners.max(axis=0)).astype(int) + 2
    patch = image[y0:y1, x0:x1]
    grey = cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY) if colour else np.ascontiguousarray(patch)
    patch_to_image = to_image - np.array([[0.0, 0.0, x0], [0.0, 0.0, y0]])
    strip = cv2.warpAffine(grey, patch_to_image, (2 * half + 1, top + bottom + 1),
                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP).astype(np.float32)
    # 1. the symmetry axis over the nose's rows: every other column on every other row, then every column and row
    #    about the best few peaks (the fuselage's and an engine's can swap places on the coarse grid)
    rows = strip[top - half_window:top + half_window + 1]
    coarse = np.arange(half - reach, half + reach + 1, 2)
    rough = mirror_scores(rows[::2], coarse, half_window)
    peaks = local_peaks(rough)
    near = coarse[peaks[np.argsort(-rough[peaks])[:COARSE_PEAKS]]]
    columns = np.unique(np.clip(near[:, None] + np.arange(-3, 4), half - reach, half + reach))
    scores = mirror_scores(rows, columns, half_window)
    # the best column about each coarse peak, most symmetric first (the first is the best of all)
    best = []
    for centre in near:
        around = np.flatnonzero(np.abs(columns - centre) <= 3)
        best.append(int(around[np.argmax(scores[around])]))
    best = np.unique(best)
    best = best[np.argsort(-scores[best], kind="stable")]
    candidates = [(float(scores[i]), columns[i] + _parabola_peak(scores, int(i))) for i in best[:max(1, axes)]]
    row["symmetry"], axis = candidates[0]
    row["axis_x"], row["axis_y"] = to_image @ np.array([axis, top, 1.0])
    if row["symmetry"][0] < min_symmetry:
        return row
    # 2. the ground contact on it: the strongest tyre-to-apron step going down, near where the template puts it.
    #    With ``axes`` > 1, an axis whose step is weak gives way to the next symmetric one with a tyre's step: an
    #    engine's round cowl can be as symmetric as the nose, but has no tyre on the apron under it. The axis is
    #    chosen on the symmetry's window (a wider one finds an engine's own step); the contact is then searched on it
    #    within ``contact_window``, the lowest step near the largest (``lowest_step``)
    band = max(1, int(round(band * height)))
    expected = top + (ground_in_template - v) * height
    lo, hi = max(2, int(expected) - half_window), min(strip.shape[0] - 3, int(expected) + half_window)
    if hi <= lo:
        return row
    tyre_rows, apron_rows = max(2, int(round(TYRE * height))), max(2, int(round(APRON * height)))
    found = None
    for symmetry, axis in candidates:
        if symmetry < min_symmetry:
            break
        c = int(round(axis))
        profile = strip[:, c - band:c + band + 1].mean(axis=1)
        contact, contrast = ground_contact(profile, lo, hi, tyre_rows, apron_rows)
        if found is None or contrast >= axis_contrast:
            found = (symmetry, axis, contrast, contact, profile)
        if contrast >= axis_contrast:
            break
    symmetry, axis, contrast, contact, profile = found
    if half_contact != half_window or lowest_step > 0:
        contact, contrast = ground_contact(profile, max(2, int(expected) - half_contact),
                                           min(strip.shape[0] - 3, int(expected) + half_contact), tyre_rows,
                                           apron_rows, lowest_step)
    row["symmetry"], row["contrast"] = symmetry, contrast
    row["axis_x"], row["axis_y"] = to_image @ np.array([axis, top, 1.0])
    if row["contrast"][0] < min_contrast:
        return row
    row["ground_x"], row["ground_y"] = to_image @ np.array([axis, contact, 1.0])
    return row


def ground_contact(profile: np.ndarray, lo: int, hi: int, above: int, below: int,
                   lowest: float = 0.0) -> tuple[float, float]:
    """(the tyre's ground contact in a grey ``profile`` going down the axis, to a sub-pixel; its step): the row in
    ``lo``..``hi`` with the largest :func:`tyre_steps` step, then the edge at the peak of the profile's central
    difference from ``below`` rows above that row to the row after it, by a parabola. The step's bands smear the
    edge over ``below`` rows: a dark line across the apron right under the tyre (a slab joint, a painted edge)
    darkens the apron band of the tyre's own edge and lends its dark row to the tyre band of the rows under it,
    and the step's best row then lay below the joint (1-2 px, a metre or two at 40-60 m); the tyre's edge is the
    larger jump. On the guidance bench's six cached sets (360 runs, each stand's exact calibration) the frames
    more than 0.5 m off in the last 15 m went from 2.4 % to 1.6 % with it. With ``lowest`` > 0 the row is instead the
    lowest peak of the step that reaches ``lowest`` of the largest in ``lo``..``hi``."""
    step = tyre_steps(profile, above, below)
    j = lo + int(np.argmax(step[lo:hi + 1]))
    if lowest > 0 and step[j] > 0:   # the lowest peak of at least ``lowest`` of the largest: under the tyre, apron
        inside = step[lo:hi + 1]
        peaks = local_peaks(inside)
        peaks = peaks[inside[peaks] >= lowest * step[j]]
        j = lo + int(peaks[-1]) if len(peaks) else j
    rise = np.zeros_like(profile)
    rise[1:-1] = 0.5 * (profile[2:] - profile[:-2])
    first = max(1, j - below)
    k = first + int(np.argmax(rise[first:j + 2]))
    return k + _parabola_peak(rise, k), float(step[j])
