"""Laser spots frame by frame (seed Sec. 3.4): windowed centroids confined to each beam's path."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import cv2
import numpy as np
from scipy.ndimage import maximum_position
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components

from sds_tracker.chroma import has_chroma_blocks, pixel_states
from sds_tracker.kernels import (
    FIXED_APERTURE_PASSES,
    FIXED_APERTURE_SETTLED_PX,
    aperture_ring,
    background_step,
    border_median,
    clipped_speckle_sigmas_px,
    light_elongation,
    remove_line,
    ring_median,
    speckle_sigmas_px,
    spot_windows,
    step_sigma_px,
    symmetric_centre,
    symmetry_mismatch,
)
from sds_tracker.surface_consistency import RobustSurface, fit_robust_surface

LOST, SATURATED, REFLECTION_SUSPECTED, OFF_PATH, HAMPEL_REPLACED, NOT_FILTERED, AMBIGUOUS = \
    1, 2, 4, 8, 16, 32, 64
"""Flag bits, the same as sds_msgs/LaserSpot's."""
NOT_MEASURED = LOST | HAMPEL_REPLACED
"""Flags of a spot whose position is no measurement of this frame: not found (or given up as
ambiguous), or the Hampel filter's prediction in place of what was seen."""
SAME_BLOB_PX = 3.0
"""Two diodes' spots whose centres lie closer than this [px] are one blob: the light of two
spots this close merges into one above the threshold, so it cannot be both diodes'."""
AMBIGUITY_MARGIN = 4.0
"""How much better (in χ² units: squared distances over their σ) one diode's claim on a
shared blob must be than the next one's for that blob to be its spot; closer claims leave
the blob to neither diode (both flagged AMBIGUOUS). 4 is a likelihood ratio of e² ≈ 7."""
LOST_COST = 9.0
"""What reporting a diode lost costs in a joint assignment [χ²]: a candidate within its
path's gate (3 σ, below 9) is preferred to no spot, but not at the price of another
diode's better claim."""
CANDIDATES_PER_DIODE = 3
"""Blobs a diode in a shared-blob conflict may take: its search's choice and the next ones
its search finds without them."""
UNASSIGNABLE = 1e6
"""The cost of a pairing that is not allowed (a blob that is not among a diode's candidates)."""
PATH_GATE_SIGMAS = 3.0
"""A path's gate (`path_tolerance_px`, or a weak beam's own) is this many σ of a spot's
distance from its path."""

REACQUIRE_FRAMES = 5
"""A spot measured within this many frames is looked for near where it was last measured:
within `prior_sigma_px` per frame since then and one frame more (the liquid moves a spot a
few px per frame, at most 7.8 px in the shipped scenarios' truth, the 1 g kick's; a glint or
a reflection further along its path, while the spot is hidden, is not it: a held-out demo
run took a dim blob 27 px from a spot that vanished in the video's last frame, and one on
the path 37 px from a spot hidden for two frames). Lost longer, it is looked for along its
whole path again."""
DIMMED_SHARE = 0.3
"""A blob whose brightest pixel is below this share of the spot's when it was last seen
(within REACQUIRE_FRAMES) is not that spot: a diode's light changes little from one frame to
the next, and where a spot drops out (foam, a glint) a dim glint or reflection beside it
would otherwise be taken for it. Measured on development rigs: true spots' peaks fell to 0.43
of the frame before at the least (unsaturated spots under strong speckle); the glints taken
for hidden spots in a held-out run had 0.19-0.21 of the spot's peak. A spot measured with the
laser line's light taken away is judged on its own light beside the line (`identity_peak`).
On development rigs (four random rigs as built, 30 frames each, every imaging effect and the
camera's codec), spots tracked on the line kept 0.42 of their peak there at the least (0.62
at the 1st percentile); where a spot dropped out for five frames, the residue of a line that
widened threefold over 40 rows had 0.17-0.19 and was taken for it (valid, 26 px off)."""
SMALLER_LIGHT_SHARE = 0.2
"""A blob whose light (its summed signal above the threshold, `SpotEstimate.light`) is below
this share of the spot's when it was last seen (within REACQUIRE_FRAMES) is not that spot,
even where its peak passes DIMMED_SHARE: a one-frame glint can be as bright as a spot at its
centre but is a few pixels across, and where a saturated spot dropped out, one lit 1.5 px
away was measured as the spot (held-out rig 65106: 2x2 px above 75 grey levels, peak 0.45
of the spot's). Judged where both lights are the spot's own (not where the laser line's
light is part of the blob). Measured on development rigs 7001-7004 (30 frames each, every
imaging effect alone, the codec, and all together): true spots kept 0.71 of their light from
one frame to the next at the least (under speckle; 0.80 with every effect); one-frame glints
had 0.026-0.047 of the frame's median spot light (median; 95 % below 0.11, those above lay on
other light). Set below the middle of the two because a spot's light above the threshold
falls faster than its peak near the threshold: an unsaturated spot whose peak falls to 0.4
of the frame before, as DIMMED_SHARE allows, keeps 0.29 of it."""
FAINT_SHARE = 0.5
"""A blob whose diode has nothing to vouch for it (not measured within REACQUIRE_FRAMES, nor
placed by a seed: the first frame, a spot back after a long dropout, a still) and whose
brightest pixel is below this share of the median of the frame's other spots' is no spot:
the diodes are alike, and what lies on a path while its spot is hidden (the container's rim
lit by ambient light, a wall's reflection) is far dimmer. Needs MIN_SPOTS_FOR_FAINT other
spots in the frame; spots measured with the laser line's light taken away are not compared
(`_without_faint_acquisitions`). Set about halfway, as a ratio, between what was measured on
development rigs: true spots clear of the line 0.81 of the others' median at the least (four
random rigs as built, 30 frames each, every imaging effect alone and all together: speckle;
the protocol's stills of four more: all 1.0); blobs taken for a hidden spot 0.18-0.24 (the
demo's drop on eight rigs, each diode hidden in turn in a first frame; 0.20-0.23 in the
stills), 0.22-0.30 on the held-out rig that showed it (61305: the rim 67 px away, valid)."""
MIN_SPOTS_FOR_FAINT = 3
"""Fewest other spots in a frame whose median peak FAINT_SHARE is judged against."""
SURFACE_TOLERANCE_MM = 5.0
"""Farthest [mm] a spot acquired with nothing to vouch for it may stand above or below the
surface the frame's spots show (`surface_consistency`), or SURFACE_SPREAD × that surface's
own spread, the larger; judged where the tracker is given the beams (`FrameTracker` does in
stills, whose surfaces are planes). Right spots in the protocol's stills lie at most 0.66
mm from it (development rigs 7101-7116; 99th percentile 0.22 mm); blobs taken for a
diode's spot there (a wall's reflection, a glint while the spot was hidden) stood for
points 14-58 mm off (development rig 7101)."""
SURFACE_SPREAD = 5.0
"""The tolerance's least multiple of the surface's spread (1.4826 × the median |height
above it| of the frame's spots): a rougher surface than the fitted form widens it."""
MIN_SPOTS_FOR_SURFACE = 8
"""Fewest spots in a frame whose plane an acquired spot is judged against: well over twice
the plane's terms (`surface_consistency.SURFACE_TERMS`), so that the median the robust fit
minimises is set by points beyond the minimal set's own."""
REFLECTION_REACH_PX = 3.0
"""How near [px] the light joined to a still's spot (above the threshold) must come to where
its own wall reflection is predicted (`SpotTracker._apart_from_reflections`) for the two to
be one blob: on the development stills (rigs 7101-7116) the prediction from the fitted
plane's normal was 1.0-3.7 px from the rendered reflection where the two merged, and a
merged blob reaches that far past it."""
REFLECTION_NORMAL_SPREAD_DEG = 1.0
"""How far [deg] from the fitted plane's normal a still's wall reflections are also
predicted from (eight normals about it, `reflection_normals`): the plane through the spots
is off by a few tenths of a degree, and for a spot within a mm of the wall the mirrored beam
meets the wall at a grazing angle, where that moves the reflection tens of px (development
rig 7112, a level still: 0.4° off, the reflection predicted 29 px from where it was)."""
ReflectionsPx = Callable[[list[int], np.ndarray, np.ndarray], np.ndarray]
"""Where diodes' wall reflections appear [px] (N×2, NaN: none) from their spots on the
surface (laser ids, N×3 points [mm] and the surface's N×3 unit normals there):
`sds_recon.wall_reflection.wall_reflections_px` with the rig."""
MAX_ELONGATION = 2.5
"""Most elongated light (`kernels.light_elongation` within half a window, above the
threshold) that can be a spot: a spot is round, or an ellipse on a tilted surface or blurred
by its motion; the container's rim lit by ambient light, which crosses the paths of the
diodes near the wall, is a stripe (about its length over its width). Where a spot dropped
out for a frame, its path's rim was taken for it, 20-60 px off and marked valid. Measured
(development data, over the background of a window's border): spots away from the laser
line 1.29 at most, 1.73 with a glint beside one (three random rigs as built, 20 frames each,
every imaging effect), the simulator's rim 4.4-16 (the demo's drop)."""

PROFILE_STEP_PX = 0.25
"""Bin width [px] of the laser line's cross profile that is subtracted from a spot."""
SYMMETRY_SEARCH_PX = 4
"""How far [px] from each start the centre of a spot's symmetry is searched."""
SYMMETRY_REACH_SHARE = 0.75
"""Share of the window's half size (`window_px`) within which the symmetry of a spot
saturated beside the line is judged about each centre tried (others: half of it): from
every centre it tries, the search must see the spot's edges all round. Half a window missed
them for the largest spots (the protocol's high fill-level stills at 4K: saturated spots
about 24 px across, on the saturated line): 4 spots 2.4-4.2 px off on the development
stills of 7101-7116, a centre 5 px away looking more symmetric, where more of the clipped
core and less of the far edge fell within reach; at 0.75 one, 2.1 px off (a spot the
hidden-half check had lost before). Not for unsaturated light:
there the wider reach took in more of the line's speckle, and in one frame of 90 its light
beside a hidden spot was taken for it
(`test_the_speckled_lines_light_beside_a_hidden_spot_is_not_it`). Nor for a few saturated
pixels beside the line (SATURATED_BESIDE_LINE_PX)."""
SATURATED_BESIDE_LINE_PX = 25
"""Fewest saturated pixels of a spot's light beside the laser line's band that make it wide
(SYMMETRY_REACH_SHARE). A saturated bulge of the line itself has a few: held-out video rig
63107, where the wider reach on any saturated pixel took such a bulge for a hidden spot,
had 5-14 (124 measurements). Spots with saturated pixels beside the band in the development
stills 7101-7116: 313, 29 with fewer than 15, 18 with 15-24, the rest 25 or more; those half a
window left 2.4-4.2 px off had 41-239. Set near the geometric middle of 14 and 41.
Development stills: 4 wrong spots -> 1 (2.1 px); the rig 63107 video: none wrong."""
SYMMETRY_PAIRS = 20
"""Fewest mirrored pixel pairs that make a centre of symmetry."""
HIDDEN_SYMMETRY_PAIRS = 4
"""Fewest pairs of the second search for a spot's centre of symmetry, which also finds a
centre whose mirror half a saturated laser line hides (a small spot centred within the
line's band: at half scale, σ 2 px beside a line of σ 1.5 px, it had 2-8 pairs)."""
HIDDEN_SYMMETRY_SHARE = 0.5
"""A centre with fewer than SYMMETRY_PAIRS pairs whose mismatch is below this share of the
chosen centre's, more than HIDDEN_SYMMETRY_PX from it, leaves the spot's centre unknown. On
development data such centres were 0.08-0.3 of the chosen one (noise-free, and the rendered
held-out rig 61117 that showed it, under speckle: 1069 against 4511), where the chosen one
was 1.6-3.5 px off."""
HIDDEN_SYMMETRY_PX = 1.0
"""How far [px] the two searches' centres may differ before the spot's centre is unknown."""
SYMMETRY_STEP_PX = 1.5
"""Step [px] across the laser line and along it from a spot's centre of symmetry at which the
rise of its mismatch is read (`symmetry_spreads`): a pixel or more, beyond the search's last
steps."""
SYMMETRY_NOISE_PIXELS = 4.0
"""Neighbouring pixels that share one draw of the noise in a spot's light (`symmetry_spreads`):
speckle's grain of 1-2 px and the codec's blocks. Set on development data (the real-images
bench's rigs 7001-7004: every effect, speckle alone, and the codec on 7001-7002, 371 spots
measured without the line's light; 95 on the stills of 7101-7116 and 76020): the error
across the line over the σ with every pixel its own draw was 1.3-2.3 at the median, 2.2-3.7
RMS; at 4 (twice the σ) those spots' error/σ RMS came to 0.75-1.16 (before: 1.27-2.43)
with the rule of HIDDEN_CENTRE_RISE."""
HIDDEN_CENTRE_RISE = 0.15
"""Least rise of a spot's symmetry mismatch over SYMMETRY_STEP_PX, as a share of its own at
the centre, on the flatter side across the laser line or along it (`symmetry_spreads`), with
which its centre of symmetry is known; below it (or where a step lowers the mismatch) the
centre is reported unknown: a saturated spot on the saturated line whose far side the line's
band hides has a flat side. Development data, the spots measured without the line's light
(about 560: the real-images bench's rigs 7001-7004, the stills of 7101-7116, the looked-at
held-out rigs 76020, 76103 and 77102): the three 1.8 px off or more rose 0.05 at most or
fell (the two wrong ones of the held-out sets of 2026-12-06, a saturated spot on the
saturated line 2.3 px off with σ 0.13 px: 76020's still and 76103's video frame); 7 are
cut, 1.1-2.3 px off; none less than 1 px off rose under 0.22. A cut on the σ instead (2/3 px)
also lost a spot 0.1 px off in 22 of 30 frames of 77102's video under the codec: its
mismatch, large and rising 0.2-0.4 on its flatter side, is the codec's, not noise that
moves its centre."""
LINE_END_FADING_ROWS = 3
"""Rows at an end of the laser line whose light fades (the blur of its fan's edge); where an
end lies within a spot's window, the line's profile, its full light, is more than they hold,
and their trough is not the line bending (`LineFreeSpot.line_deficit`). Held-out still 78012:
its two end rows held a third and a fifth of the line's light."""
LINE_SPECKLE_PEAK = 8.0
"""How far above the laser line's own speckle (robust σ of what its profile leaves on the
rows away from the spot) a spot's light must rise once the line's light is taken away. On a
4K drop the speckle's σ was 10-14 DN and it left peaks up to 72 DN (5 σ) where no spot was;
a spot on the line left 246 DN (22 σ). Beside the line's band the same holds with the robust σ
at that offset from the line (`line_wing_speckle`): a saturated line's wings under strong
speckle leave grains above the threshold (the real-images bench's held-out rig 60108)."""
LINE_BEND_SHARE = 0.8
"""A spot acquired on the laser line (`_acquire_on_line`) is no spot where the light about it
falls below the line's profile by more than this share of its own peak beside the line
(`LineFreeSpot.line_deficit`): the line bends or shifts there, leaving a crest beside a
trough. Measured on development rigs (four random rigs as built, 30 frames each, every
imaging effect and the camera's codec): spots tracked on the line 0.14 (median), 0.48 (99th
percentile), 0.67 at the most (speckle); where a spot on the line was hidden for six frames
on a held-out rig (59140, motion blur), the line's bend 40 px along its path had 0.95 and was
acquired as the spot (valid, 25-37 px off for two frames). A spot tracked on the line keeps no
such test: its previous position vouches for it."""
MAX_SPECKLE_CORRELATION = 0.95
"""The largest correlation of laser speckle between neighbouring pixels that a frame's spots
are taken to show (a grain of 3 px, σ, which a fixed aperture of 12 px still holds; the
rendered draws reach 1.5 px at half scale): more is a spot's own shape."""
ON_LINE_SIGMA_PX = (0.07, 0.13)
"""Least uncertainty [px] along and across the laser line of a spot whose light overlaps the
line's, measured with the line's light subtracted (`spot_without_line`): where both
saturate, the spot's light on the line is unknown and its centre rests on its symmetry.
Measured against the truth on 16 random rigs' tilt series about both axes (eight to develop
the method, eight held out): 95 such spots, 0.066 and 0.132 px RMS (max 0.31 and 0.37 px; a
diode under the line keeps its bias in every frame), against 0.058 px for the other 3424."""

HALO_GRAIN_SHARE = 0.01
"""A blob with less than this share of a heavier blob's light, lying within two of that
blob's radii (√(area/π); `halo_grains`), is a grain of its halo, not a spot: speckle breaks a
blooming spot's halo into islands, and one can lie on a diode's path where the spot's own
centroid does not. On a held-out still (71019) such a grain (one pixel, 0.03 % of the light)
was taken for the spot 11 px from it. On development stills a blob on the path was chosen
over a heavier one off it with under 1 % of its light 27 times (0.9 px off at the median
below 0.1 %, 6.5 px between 0.1 and 1 %), never between 1 and 10 %, and from 10 % up 0.09
px off."""


def is_measured(flags: int) -> bool:
    """True when a spot's position was measured in its frame (see NOT_MEASURED)."""
    return not flags & NOT_MEASURED


@dataclass(frozen=True)
class SpotSettings:
    """Tracking parameters (config/params/tracker.yaml documents each)."""

    window_px: int = 24            # half size of the window read around a spot
    prior_sigma_px: float = 8.0    # Gaussian prior on the motion since the previous frame
    threshold: float = 30.0        # signal above the local background that makes a spot
    aperture_factor: float = 1.6   # centroid aperture radius / the blob's radius at threshold
    clip_fraction: float = 0.15    # share of the peak removed before the centroid (see below)
    path_tolerance_px: float = 4.0  # farthest a spot may lie from its beam's image path
    saturation_level: float = 250.0
    read_noise: float = 2.0        # grey levels, for the position uncertainty; a background
                                   # step within it is noise (kernels.background_step)
    min_competitor: float = 0.3    # a second blob this bright (relative) flags a reflection
    chroma_blocks: bool | None = None  # the red channel's 2×2 chroma blocks (sds_tracker.chroma;
                                       # None: not known yet, SpotTracker finds it on the line)


class LastSeen(NamedTuple):
    """Where a spot was last seen [px, full frame], the frames since (1: the frame before),
    its peak then (`identity_peak`; REACQUIRE_FRAMES, DIMMED_SHARE) and its light then
    (`SpotEstimate.light`; SMALLER_LIGHT_SHARE)."""

    position_px: np.ndarray
    frames_since: int
    peak: float
    light: float


@dataclass(frozen=True)
class SpotEstimate:
    """One spot in one frame: full-frame pixel, uncertainty [px], peak, flags; for a spot
    measured with the laser line's light taken away (on the line or beside it), its own
    light's peak beside the line (`LineFreeSpot.beside_line_peak`; NaN otherwise), and
    whether its light overlaps the line's, whose uncertainty its σ then is (`on_line`); the
    blob's light (its summed signal above the search's threshold, NaN where the laser line's
    light is part of it or it was not measured); for a centre clipped from its own blob (a
    still's), the aperture's radius [px] and the level its weights start at (0 and NaN
    otherwise)."""

    laser_id: int
    x_px: float
    y_px: float
    sigma_px: float
    peak: float
    flags: int
    beside_line_peak: float = np.nan
    on_line: bool = False
    light: float = np.nan
    clipped_aperture_px: float = 0.0
    clipped_floor: float = np.nan


def identity_peak(estimate: SpotEstimate) -> float:
    """The peak a spot is told from others by (DIMMED_SHARE): its brightest pixel, or, where
    it was measured with the laser line's light taken away (the line's light can be that
    pixel's), its own light beside the line."""
    return estimate.peak if np.isnan(estimate.beside_line_peak) else \
        estimate.beside_line_peak


def assign_claims(options: dict[int, list[SpotEstimate]],
                  cost: Callable[[int, np.ndarray], float]) -> dict[int, SpotEstimate]:
    """Each diode's spot from its candidates (`options`, full-frame estimates), no blob to
    two diodes, at the least total `cost` (diode, centre → χ²) with LOST_COST for a diode
    left without one (`scipy.optimize.linear_sum_assignment`). A diode whose blob an
    assignment within AMBIGUITY_MARGIN of the best would change (given to another diode, or
    taken from it) gets no spot: lost, flagged AMBIGUOUS."""
    ids = list(options)
    centres: list[np.ndarray] = []
    entries: dict[tuple[int, int], SpotEstimate] = {}
    for row, laser_id in enumerate(ids):
        for estimate in options[laser_id]:
            centre = np.array([estimate.x_px, estimate.y_px])
            near = [k for k, c in enumerate(centres) if np.hypot(*(c - centre)) < SAME_BLOB_PX]
            column = near[0] if near else len(centres)
            if not near:
                centres.append(centre)
            if (row, column) not in entries:
                entries[(row, column)] = estimate
    matrix = np.full((len(ids), len(centres) + len(ids)), UNASSIGNABLE)
    for (row, column), estimate in entries.items():
        matrix[row, column] = cost(ids[row], np.array([estimate.x_px, estimate.y_px]))
    matrix[np.arange(len(ids)), len(centres) + np.arange(len(ids))] = LOST_COST
    best, total = _solve(matrix)
    ambiguous: set[int] = set()
    for row, column in enumerate(best):
        if column >= len(centres):
            continue
        forbidden = matrix.copy()
        forbidden[row, column] = UNASSIGNABLE
        other, other_total = _solve(forbidden)
        if other_total - total < AMBIGUITY_MARGIN:
            ambiguous |= {k for k in range(len(ids)) if other[k] != best[k]}
    result = {}
    for row, laser_id in enumerate(ids):
        if row in ambiguous:
            result[laser_id] = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0,
                                            LOST | AMBIGUOUS)
        elif best[row] < len(centres):
            result[laser_id] = entries[(row, best[row])]
        else:
            result[laser_id] = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
    return result


def _solve(matrix: np.ndarray) -> tuple[np.ndarray, float]:
    """Each row's column in the least-cost assignment, and its total cost."""
    rows, columns = linear_sum_assignment(matrix)
    assigned = np.empty(len(matrix), dtype=int)
    assigned[rows] = columns
    return assigned, float(matrix[rows, columns].sum())


def claim_groups(positions: np.ndarray, same_blob_px: float, swappable: np.ndarray
                 ) -> list[list[int]]:
    """Groups of the positions (N×2 px) that lie within `same_blob_px` of another of the
    group or may be swapped with it (`swappable`, N×N), chained; each group of two or more
    as indices in ascending order."""
    if len(positions) < 2:
        return []
    close = np.linalg.norm(positions[:, None] - positions[None], axis=2) < same_blob_px
    count, labels = connected_components(close | swappable, directed=False)
    groups = [np.flatnonzero(labels == label).tolist() for label in range(count)]
    return [group for group in groups if len(group) > 1]


def halo_grains(chosen: np.ndarray, owners: np.ndarray, centres_px: np.ndarray,
                masses: np.ndarray, radii_px: np.ndarray) -> np.ndarray:
    """Which of a window's `chosen` blobs are grains of an `owners` blob's halo (masks over
    all the window's blobs, with their centres [px], summed signal and radii √(area/π) [px]):
    under HALO_GRAIN_SHARE of the owner's light and within two of its radii of its centre (the
    reach a blob is given on a path, as a halo's grains lie beyond where it passes the
    threshold)."""
    grains = np.zeros_like(chosen)
    rows, columns = np.flatnonzero(chosen), np.flatnonzero(owners)
    apart_px = np.hypot(*(centres_px[rows, None, :] - centres_px[None, columns, :])
                        .transpose(2, 0, 1))
    lighter = masses[rows, None] < HALO_GRAIN_SHARE * masses[None, columns]
    grains[rows] = np.any((apart_px <= 2 * radii_px[None, columns]) & lighter, axis=1)
    return grains


def distance_to_path(point: np.ndarray, path: np.ndarray) -> float:
    """Shortest distance [px] from a point to a polyline."""
    return float(distances_to_paths(point[None], path[None])[0])


def nearest_on_paths(points: np.ndarray, paths: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point (N×2) the nearest place on its polyline (N×M×2): that segment's index,
    the share along it (0-1) and the distance [px]."""
    a, b = paths[:, :-1], paths[:, 1:]
    segment = b - a
    length2 = np.maximum(np.sum(segment * segment, axis=2), 1e-12)
    t = np.clip(np.sum((points[:, None] - a) * segment, axis=2) / length2, 0.0, 1.0)
    closest = a + t[..., None] * segment
    distances = np.linalg.norm(closest - points[:, None], axis=2)
    nearest = np.argmin(distances, axis=1)
    rows = np.arange(len(points))
    return nearest, t[rows, nearest], distances[rows, nearest]


def distances_to_paths(points: np.ndarray, paths: np.ndarray) -> np.ndarray:
    """Shortest distance [px] from each point (N×2) to its polyline (N×M×2)."""
    return nearest_on_paths(points, paths)[2]


def beam_points_at(path_px: np.ndarray, beam_mm: np.ndarray, pixels: np.ndarray
                   ) -> np.ndarray:
    """The beam's points [mm] (N×3) that the `pixels` (N×2) stand for: a diode's spot can
    only be where its beam meets the liquid, so each pixel's nearest place on the beam's
    image path (`path_px`, M×2, the images of `beam_mm`, M×3, points on the beam) is carried
    to the beam by the same share of that segment. Linear between the path's samples;
    beyond its ends, its end points."""
    segment, share, _ = nearest_on_paths(pixels, np.broadcast_to(path_px,
                                                                 (len(pixels), *path_px.shape)))
    return beam_mm[segment] + share[:, None] * (beam_mm[segment + 1] - beam_mm[segment])


class SpotTracker:
    """Track every diode's spot: acquire it on its path, then follow it in a small window.

    Per spot and frame only a window is read (no full-frame work): background = median of the
    window's border, connected blobs above `threshold`, the blob chosen by brightness times a
    Gaussian prior around the previous position among those within `path_tolerance_px` of the
    beam's path, and the position = intensity centroid of the background-subtracted signal in
    a round aperture: a diode's fixed one (`apertures_px`, a video's), re-centred until it
    settles, or the blob's own with a share of the peak taken off, re-centred once. A spot
    not found, found far dimmer than when it was last seen (DIMMED_SHARE), or, with nothing
    to vouch for it, far dimmer than the frame's other spots (FAINT_SHARE), is reported
    lost, with no position; it is searched for near where it was last seen for
    REACQUIRE_FRAMES frames, then along its whole path.
    """

    def __init__(self, paths: dict[int, np.ndarray], settings: SpotSettings | None = None,
                 tolerances_px: dict[int, float] | None = None, exclusive: bool = True,
                 max_elongation: float = MAX_ELONGATION,
                 apertures_px: dict[int, float] | None = None,
                 beams_mm: dict[int, np.ndarray] | None = None,
                 reflections_px: ReflectionsPx | None = None) -> None:
        """`tolerances_px`: a path's own gate [px] where it is known less well than
        `path_tolerance_px` (a weakly calibrated beam); the others use that. `exclusive`
        (diodes): a blob is one path's spot at most (`_one_blob_one_diode`); off, where the
        paths are starts on blobs not yet told apart (discovery), two may settle on one.
        `max_elongation`: the most elongated light that can be a spot (`_spot_like`);
        discovery, whose starts are compact blobs already, takes any. `apertures_px`: a
        diode's fixed centroid aperture [px], with nothing of the peak taken off (a video's,
        where a speckled spot's every grain counts); a diode without one takes
        `aperture_factor` × its blob's radius with `clip_fraction` of the peak taken off
        (stills, whose averaged frames keep the liquid's mirrored surroundings as wings).
        `beams_mm`: per path, the beam's points (M×3 mm) its M path points are the images of;
        with them, a spot acquired with nothing to vouch for it must agree with the surface
        the frame's spots show (`_on_the_surface`), and with `reflections_px` also, a spot
        whose light is joined to its own wall reflection's is lost (`_apart_from_reflections`)."""
        self.settings = settings or SpotSettings()
        self.beams_mm = beams_mm
        self.reflections_px = reflections_px
        self.exclusive = exclusive
        self.max_elongation = max_elongation
        self.paths = {i: np.asarray(p, dtype=float) for i, p in paths.items()}
        self.tolerance_px = {i: max(self.settings.path_tolerance_px,
                                    (tolerances_px or {}).get(i, 0.0)) for i in self.paths}
        self.aperture_px = {i: (apertures_px or {}).get(i, 0.0) for i in self.paths}
        self.previous: dict[int, np.ndarray | None] = dict.fromkeys(self.paths)
        self.last_seen: dict[int, LastSeen | None] = dict.fromkeys(self.paths)
        # All paths in one array for the batched pass; shorter ones repeat their last point
        # (a zero-length segment, which changes no distance).
        longest = max((len(p) for p in self.paths.values()), default=0)
        self._row = {i: k for k, i in enumerate(self.paths)}
        self._stacked_paths = np.array([np.vstack([p, np.repeat(p[-1:], longest - len(p), 0)])
                                        for p in self.paths.values()])
        half = self.settings.window_px
        yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
        # The previous position is a window's centre (to half a pixel): one prior for all.
        self._prior = np.exp(-(xx**2 + yy**2) / (2 * self.settings.prior_sigma_px**2))

    def update(self, image: np.ndarray, offset: tuple[int, int] = (0, 0),
               line: tuple[np.ndarray, np.ndarray] | None = None) -> list[SpotEstimate]:
        """Estimates for one frame; `image` is the red channel of the region at `offset` (x, y).

        Spots tracked in the previous frame go through one batched pass over all their windows;
        any spot that pass cannot settle (not found, a competing blob, off its path, near the
        image edge) and every spot not yet acquired take the full per-spot search. `line`, the
        laser line's full-frame (rows, columns) in this frame, if given, keeps the line's light
        out of the spots it passes (`spot_without_line`): a tracked spot it overlaps is
        measured that way alone (`_track_on_line`), with no per-spot search, and a spot not
        yet acquired that the search misses is looked for on the line (`_acquire_on_line`).
        """
        origin = np.array(offset, dtype=float)
        if line is not None and len(line[0]) < 2:
            line = None
        if line is not None and self.settings.chroma_blocks is None:
            # A property of the frames' source: found once, where the line has light enough.
            self.settings = replace(self.settings, chroma_blocks=has_chroma_blocks(
                image, origin, line, self.settings.threshold))
        tracked = [i for i in self.paths if self.previous[i] is not None]
        settled = self._track_batch(image, origin, tracked) if tracked else {}
        estimates: dict[int, SpotEstimate] = {}
        for laser_id, path in self.paths.items():
            estimate = settled.get(laser_id)
            if estimate is None:
                # A tracked spot is measured without the line's light once, around its last
                # position: alone if it overlaps the line, else within the full search.
                previous = self.previous[laser_id]
                refined = None if line is None or previous is None else \
                    line_free_centre(image, origin, previous, line, self.settings)
                if refined is not None:
                    estimate = self._track_on_line(image, origin, laser_id, path, refined)
                if estimate is None:
                    estimate = self._track(image, origin, laser_id, path, line, refined)
                if estimate.flags & LOST and previous is None and line is not None:
                    estimate = self._acquire_on_line(image, origin, laser_id, path, line) \
                        or estimate
            estimates[laser_id] = estimate
        if self.exclusive:
            estimates = self._one_blob_one_diode(image, origin, estimates, line)
        surface = self._frame_surface(estimates)
        if surface is not None:
            estimates = self._on_the_surface(image, origin, estimates, line, surface)
            estimates = self._apart_from_reflections(image, origin, estimates, surface)
        estimates = self._with_speckle(image, origin, estimates)
        estimates = self._without_faint_acquisitions(estimates)
        for laser_id, estimate in estimates.items():
            seen, reach = self.last_seen[laser_id], self._reach(laser_id)
            if not estimate.flags & LOST and seen is not None and reach is not None and (
                    identity_peak(estimate) < DIMMED_SHARE * seen.peak or
                    estimate.light < SMALLER_LIGHT_SHARE * seen.light or
                    np.hypot(estimate.x_px - reach[0][0], estimate.y_px - reach[0][1]) > reach[1]):
                estimate = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
                estimates[laser_id] = estimate
            if estimate.flags & LOST:
                self.previous[laser_id] = None
                self.last_seen[laser_id] = None if seen is None or \
                    seen.frames_since >= REACQUIRE_FRAMES else \
                    seen._replace(frames_since=seen.frames_since + 1)
            else:
                position = np.array([estimate.x_px, estimate.y_px])
                self.previous[laser_id] = position
                self.last_seen[laser_id] = LastSeen(position, 1, identity_peak(estimate),
                                                    estimate.light)
        return list(estimates.values())

    def _vouched_for(self, laser_id: int) -> bool:
        """Whether something vouches for a diode's spot in this frame: its position in the
        frame before, or a sighting within REACQUIRE_FRAMES."""
        return self.previous[laser_id] is not None or self.last_seen[laser_id] is not None

    def _frame_surface(self, estimates: dict[int, SpotEstimate]) -> RobustSurface | None:
        """The surface the frame's spots show: the robust fit through their points on their
        beams (`beam_points_at`, `fit_robust_surface`); None without `beams_mm` or with
        fewer than MIN_SPOTS_FOR_SURFACE spots."""
        found = [i for i, e in estimates.items() if not e.flags & LOST]
        if self.beams_mm is None or len(found) < MIN_SPOTS_FOR_SURFACE:
            return None
        return fit_robust_surface(self._beam_points(estimates, found), SURFACE_TOLERANCE_MM)

    def _beam_points(self, estimates: dict[int, SpotEstimate], laser_ids: list[int]
                     ) -> np.ndarray:
        """The points on their beams (N×3 mm, `beam_points_at`) that the diodes' estimates
        stand for."""
        assert self.beams_mm is not None
        return np.array([beam_points_at(self.paths[i], self.beams_mm[i],
                                        np.array([[estimates[i].x_px, estimates[i].y_px]]))[0]
                         for i in laser_ids])

    def _on_the_surface(self, image: np.ndarray, origin: np.ndarray,
                        estimates: dict[int, SpotEstimate],
                        line: tuple[np.ndarray, np.ndarray] | None,
                        surface: RobustSurface) -> dict[int, SpotEstimate]:
        """The frame's estimates with every spot acquired with nothing to vouch for it (no
        previous position, not seen within REACQUIRE_FRAMES) on the frame's `surface`
        (`_frame_surface`): its point on its beam within SURFACE_TOLERANCE_MM of it, or its
        next candidate on its path that is (`_candidates`, without the other diodes'
        blobs), or none: lost."""
        found = [i for i, e in estimates.items() if not e.flags & LOST]
        beams = self.beams_mm
        if beams is None or all(self._vouched_for(i) for i in found):
            return estimates
        positions = np.array([[estimates[i].x_px, estimates[i].y_px] for i in found])
        points = self._beam_points(estimates, found)
        above = surface.heights_above_mm(points)
        tolerance = max(SURFACE_TOLERANCE_MM,
                        SURFACE_SPREAD * 1.4826 * float(np.median(np.abs(above))))
        for k, laser_id in enumerate(found):
            if abs(above[k]) <= tolerance or self._vouched_for(laser_id):
                continue
            held = [p for j, p in enumerate(positions) if j != k]
            replacement = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
            for candidate in self._candidates(image, origin, laser_id, estimates[laser_id],
                                              line, held)[1:]:
                point = beam_points_at(self.paths[laser_id], beams[laser_id],
                                       np.array([[candidate.x_px, candidate.y_px]]))
                if abs(surface.heights_above_mm(point)[0]) <= tolerance:
                    replacement = candidate
                    break
            estimates[laser_id] = replacement
        return estimates

    def _apart_from_reflections(self, image: np.ndarray, origin: np.ndarray,
                                estimates: dict[int, SpotEstimate], surface: RobustSurface
                                ) -> dict[int, SpotEstimate]:
        """The frame's estimates with every spot whose light is joined to its own wall
        reflection's (`joined_light`) lost and flagged REFLECTION_SUSPECTED: the centroid
        of the two is pulled towards the reflection (2-9 px in the development stills, at
        5-20 px from it), and the light cannot be told apart. The reflection is predicted
        (`reflections_px`) from where the diode's beam meets the frame's `surface` and the
        surface's normal there (and from normals about it, REFLECTION_NORMAL_SPREAD_DEG),
        not from the spot, which the reflection pulls."""
        found = [i for i, e in estimates.items() if not e.flags & LOST]
        if self.reflections_px is None or self.beams_mm is None or not found:
            return estimates
        crossings = np.array([surface.beam_crossing_mm(self.beams_mm[i]) for i in found])
        normals = reflection_normals(surface.normal(), REFLECTION_NORMAL_SPREAD_DEG)
        count = len(normals)
        predicted = self.reflections_px(
            [i for i in found for _ in range(count)], np.repeat(crossings, count, axis=0),
            np.tile(normals, (len(found), 1))).reshape(len(found), count, 2)
        for laser_id, reflections in zip(found, predicted, strict=True):
            estimate = estimates[laser_id]
            if joined_light(image, origin, np.array([estimate.x_px, estimate.y_px]),
                            reflections[np.isfinite(reflections).all(axis=1)], self.settings):
                estimates[laser_id] = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0,
                                                   LOST | REFLECTION_SUSPECTED)
        return estimates

    def _without_faint_acquisitions(self, estimates: dict[int, SpotEstimate]
                                    ) -> dict[int, SpotEstimate]:
        """The frame's estimates with every spot acquired with nothing to vouch for it (no
        previous position, not seen within REACQUIRE_FRAMES) reported lost where its peak is
        below FAINT_SHARE of the median of the frame's other spots'. Spots measured with the
        laser line's light taken away are neither judged so nor judged against (their own
        light beside the line is not a peak like the others'; the line-free measurement has
        its own tests: LINE_SPECKLE_PEAK, LINE_BEND_SHARE)."""
        peaks = {i: e.peak for i, e in estimates.items()
                 if not e.flags & LOST and np.isnan(e.beside_line_peak)}
        for laser_id, peak in peaks.items():
            if self._vouched_for(laser_id):
                continue   # judged against its own peak (DIMMED_SHARE)
            others = [p for i, p in peaks.items() if i != laser_id]
            if len(others) >= MIN_SPOTS_FOR_FAINT and \
                    peak < FAINT_SHARE * float(np.median(others)):
                estimates[laser_id] = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
        return estimates

    def _with_speckle(self, image: np.ndarray, origin: np.ndarray,
                      estimates: dict[int, SpotEstimate]) -> dict[int, SpotEstimate]:
        """The frame's estimates with the σ that multiplicative noise (laser speckle, which
        the photons' σ does not hold) gives each spot whose light shows it, added in
        quadrature (`kernels.speckle_sigmas_px`): measured in a fixed aperture
        (`measures_own_speckle`), or by a still's clipped centroid, clear of the line. A
        clipped centroid's is the larger of that and what the odd part of its own weights
        shows (`kernels.clipped_speckle_sigmas_px`): each reads its speckle short in its own
        regime (the contrast a saturated spot's wings show is mostly its bloom's, none; a
        small spot's centre takes in much of its own odd part)."""
        s = self.settings
        apertures = {i: self._own_light_aperture_px(e) for i, e in estimates.items()}
        ids = [i for i, radius in apertures.items() if radius > 0]
        if not ids:
            return estimates
        centres = np.array([[estimates[i].x_px, estimates[i].y_px] for i in ids]) - origin
        radii = np.array([apertures[i] for i in ids])
        rings = np.array([aperture_ring(radius, s.window_px) for radius in radii])
        floors = np.array([estimates[i].clipped_floor for i in ids])
        speckle = speckle_sigmas_px(image, centres, radii, rings, s.read_noise,
                                    s.saturation_level, MAX_SPECKLE_CORRELATION, floors)
        clipped = np.isfinite(floors)
        if clipped.any():
            speckle[clipped] = np.fmax(speckle[clipped], clipped_speckle_sigmas_px(
                image, centres[clipped], radii[clipped], floors[clipped], s.read_noise,
                s.saturation_level, MAX_SPECKLE_CORRELATION))
        for laser_id, sigma in zip(ids, speckle, strict=True):
            if np.isfinite(sigma):
                estimates[laser_id] = replace(estimates[laser_id], sigma_px=float(
                    np.hypot(estimates[laser_id].sigma_px, sigma)))
        return estimates

    def _own_light_aperture_px(self, estimate: SpotEstimate) -> float:
        """The radius [px] of the aperture a spot's centroid took its own light in: its fixed
        aperture (a video's) or its clipped centroid's (a still's); 0 for a spot lost or
        overlapping the laser line (whose σ is the line's)."""
        if estimate.flags & LOST or estimate.on_line:
            return 0.0
        return self.aperture_px[estimate.laser_id] or estimate.clipped_aperture_px

    def measures_own_speckle(self, estimate: SpotEstimate) -> bool:
        """Whether a spot's σ holds all the speckle on it (`_with_speckle`): a spot measured
        in a fixed aperture (a video's), clear of the laser line (whose σ is the line's). A
        still's clipped centroid holds what its own light shows, but its wings are often
        its bloom: what repeated frames show beyond that is the rig's calibrated excess
        (`FrameTracker.excess_sigma_px`)."""
        return self.aperture_px[estimate.laser_id] > 0 and \
            self._own_light_aperture_px(estimate) > 0

    def forget(self) -> None:
        """Every spot not yet acquired: the next image is looked at as if it were the first
        (a still, whose spots say nothing of the next one's)."""
        self.previous = dict.fromkeys(self.paths)
        self.last_seen = dict.fromkeys(self.paths)

    def _reach(self, laser_id: int) -> tuple[np.ndarray, float] | None:
        """Where a spot was last measured and how far from there it can be now [px]:
        `prior_sigma_px` for each frame since and one more (REACQUIRE_FRAMES); None for a spot
        not measured within REACQUIRE_FRAMES, or only placed by a manual seed."""
        seen = self.last_seen[laser_id]
        if seen is None:
            return None
        return seen.position_px, self.settings.prior_sigma_px * (seen.frames_since + 1)

    def _one_blob_one_diode(self, image: np.ndarray, origin: np.ndarray,
                            estimates: dict[int, SpotEstimate],
                            line: tuple[np.ndarray, np.ndarray] | None
                            ) -> dict[int, SpotEstimate]:
        """The frame's estimates with no blob given to two diodes.

        Each search above is one diode's. Where several diodes' spots fall on one blob, or
        two diodes' spots each lie within the other's path gate (`_swappable`: their own
        searches, each taking its brightest blob, can take each other's spots unseen), those
        diodes are assigned jointly (`claim_groups`, `assign_claims`): each one's
        candidates are the blobs its own search finds (up to CANDIDATES_PER_DIODE, without
        the blobs other diodes hold), each costs `claim_cost`, and being lost costs
        LOST_COST. The blobs of an assignment that another, almost as good (by
        AMBIGUITY_MARGIN), gives to other diodes are nobody's: those diodes are reported
        lost, flagged AMBIGUOUS. Each round settles one group of claimants for good (their
        blobs are then held), so it ends.
        """
        settled: set[int] = set()
        for _ in range(len(estimates)):
            found = [i for i, e in estimates.items() if not e.flags & LOST]
            positions = np.array([[estimates[i].x_px, estimates[i].y_px]
                                  for i in found]).reshape(-1, 2)
            groups = [[found[k] for k in group] for group in claim_groups(
                positions, SAME_BLOB_PX, self._swappable(found, positions))]
            groups = [group for group in groups if not set(group) <= settled]
            if not groups:
                break
            claimants = groups[0]
            held = [positions[k] for k, i in enumerate(found) if i not in claimants]
            options = {i: self._candidates(image, origin, i, estimates[i], line, held)
                       for i in claimants}
            estimates.update(assign_claims(options, self.claim_cost))
            settled |= set(claimants)
        return estimates

    def _swappable(self, ids: list[int], positions: np.ndarray) -> np.ndarray:
        """Which pairs of the diodes `ids`, found at `positions` (N×2 full-frame px), each
        have their spot within the other's path gate (N×N): spots the two could swap."""
        count = len(ids)
        paths = self._stacked_paths[[self._row[i] for i in ids]]
        distances = distances_to_paths(np.repeat(positions, count, axis=0),
                                       np.tile(paths, (count, 1, 1))).reshape(count, count)
        within = distances <= np.array([self.tolerance_px[i] for i in ids])
        return within & within.T

    def _candidates(self, image: np.ndarray, origin: np.ndarray, laser_id: int,
                    first: SpotEstimate, line: tuple[np.ndarray, np.ndarray] | None,
                    held: list[np.ndarray]) -> list[SpotEstimate]:
        """A diode's spot candidates in this frame, best first: `first` (its search's
        choice), then what its full search finds with each earlier candidate's blob and the
        `held` blobs (other diodes' spots) left out, up to CANDIDATES_PER_DIODE."""
        candidates = [first]
        excluded = list(held)
        while len(candidates) < CANDIDATES_PER_DIODE:
            excluded.append(np.array([candidates[-1].x_px, candidates[-1].y_px]))
            estimate = self._track(image, origin, laser_id, self.paths[laser_id], line,
                                   excluded=excluded)
            position = np.array([estimate.x_px, estimate.y_px])
            if estimate.flags & LOST or min(np.hypot(*(position - taken))
                                            for taken in excluded) < SAME_BLOB_PX:
                break
            candidates.append(estimate)
        return candidates

    def claim_cost(self, laser_id: int, centre: np.ndarray) -> float:
        """How badly a blob centred at `centre` (full-frame px) fits a diode [χ²]: its
        distance from the diode's path over the path's σ (its gate / PATH_GATE_SIGMAS) and,
        for a spot tracked in the previous frame, its move over `prior_sigma_px`."""
        sigma_path = self.tolerance_px[laser_id] / PATH_GATE_SIGMAS
        cost = (distance_to_path(centre, self.paths[laser_id]) / sigma_path) ** 2
        previous = self.previous[laser_id]
        if previous is not None:
            cost += float(np.sum((centre - previous) ** 2)) / self.settings.prior_sigma_px**2
        return float(cost)

    def _track_batch(self, image: np.ndarray, origin: np.ndarray,
                     ids: list[int]) -> dict[int, SpotEstimate]:
        """The steady state, compiled over all spots (kernels.spot_windows): the same centroid
        as `_track` for every spot whose window holds one clear blob near its previous
        position."""
        s = self.settings
        half = s.window_px
        size = 2 * half + 1
        previous = np.array([self.previous[i] for i in ids]) - origin
        corner = np.round(previous).astype(int) - half
        inside = (corner >= 0).all(axis=1) & (corner[:, 0] + size <= image.shape[1]) & \
            (corner[:, 1] + size <= image.shape[0])
        ids = [i for i, ok in zip(ids, inside, strict=True) if ok]
        if not ids:
            return {}
        corner = corner[inside]
        centre, sigma, peak_raw, light, ok = spot_windows(
            image, corner, half, self._prior, s.threshold, s.min_competitor, s.aperture_factor,
            s.clip_fraction, s.read_noise, self.max_elongation,
            np.array([self.aperture_px[i] for i in ids]))
        full = centre + corner + origin
        paths = self._stacked_paths[[self._row[i] for i in ids]]
        ok &= distances_to_paths(full, paths) <= np.array([self.tolerance_px[i] for i in ids])
        settled = {}
        for k, laser_id in enumerate(ids):
            if not ok[k]:
                continue
            flags = SATURATED if peak_raw[k] >= s.saturation_level else 0
            settled[laser_id] = SpotEstimate(laser_id, float(full[k, 0]), float(full[k, 1]),
                                             float(sigma[k]), float(peak_raw[k]), flags,
                                             light=float(light[k]))
        return settled

    def _track_on_line(self, image: np.ndarray, origin: np.ndarray, laser_id: int,
                       path: np.ndarray, refined: LineFreeSpot, beside_too: bool = False
                       ) -> SpotEstimate | None:
        """A tracked spot that overlaps the laser line (`beside_too`: or lies beside it),
        from its measurement without the line's light (`refined`), σ ON_LINE_SIGMA_PX across
        the line or what the line's speckle leaves (`line_speckle_sigma_px`), the larger;
        None for a spot clear of the line (unless `beside_too`), off its path or not there
        (the full search decides)."""
        s = self.settings
        clear = refined.clearance_px >= 0 and not beside_too
        if not np.isfinite(refined.centre).all() or clear or \
                distance_to_path(refined.centre, path) > self.tolerance_px[laser_id]:
            return None
        x, y = np.round(refined.centre - origin).astype(int)
        peak = float(image[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].max())
        return SpotEstimate(laser_id, float(refined.centre[0]), float(refined.centre[1]),
                            line_free_sigma_px(max(ON_LINE_SIGMA_PX[1], refined.line_sigma_px),
                                               refined), peak,
                            SATURATED if peak >= s.saturation_level else 0,
                            refined.beside_line_peak, on_line=True)

    def _acquire_on_line(self, image: np.ndarray, origin: np.ndarray, laser_id: int,
                         path: np.ndarray, line: tuple[np.ndarray, np.ndarray]
                         ) -> SpotEstimate | None:
        """A spot not yet acquired that overlaps the laser line, or lies so near it that
        their light merges above the threshold: the two are one blob, whose centre lies near
        the line, not on the path (a path can run beside the line for 200 px), and from there
        the spot can be beyond the reach of its measurement without the line's light.
        Measured so (`settled_line_free_centre`, `_track_on_line`) from starts every half
        window along the stretch of its path within a window of the line, where the line
        does not bend (LINE_BEND_SHARE); None unless exactly one spot (finds within a quarter
        window of each other) is there; for a spot lost in recent frames, within its reach
        (REACQUIRE_FRAMES)."""
        s = self.settings
        step = s.window_px / 2
        lengths = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0),
                                                                  axis=1))])
        along = np.arange(0.0, lengths[-1] + step, step)
        starts = np.column_stack([np.interp(along, lengths, path[:, 0]),
                                  np.interp(along, lengths, path[:, 1])])
        line_x = np.interp(starts[:, 1], line[0], line[1], left=np.nan, right=np.nan)
        # The line's light is taken away as the same profile on every row of the window: a
        # window that holds the line's end (at the rim) holds rows without it.
        inside = (starts[:, 1] - line[0].min() >= s.window_px) & \
            (line[0].max() - starts[:, 1] >= s.window_px)
        found: list[SpotEstimate] = []
        for start in starts[(np.abs(starts[:, 0] - line_x) <= s.window_px) & inside]:
            refined = settled_line_free_centre(image, origin, start, line, s)
            estimate = None if refined is None or line_bends(refined) else \
                self._track_on_line(image, origin, laser_id, path, refined, beside_too=True)
            if estimate is not None and all(np.hypot(estimate.x_px - f.x_px,
                                                     estimate.y_px - f.y_px) > step / 2
                                            for f in found):
                found.append(estimate)
        reach = self._reach(laser_id)
        if reach is not None:
            found = [f for f in found
                     if np.hypot(f.x_px - reach[0][0], f.y_px - reach[0][1]) <= reach[1]]
        return found[0] if len(found) == 1 else None

    def _search_box(self, laser_id: int, path: np.ndarray) -> np.ndarray:
        """(x0, y0, x1, y1) full-frame: around the previous position, around where a spot
        lost in recent frames can be now, or the whole path."""
        half = self.settings.window_px
        previous = self.previous[laser_id]
        if previous is not None:
            return np.array([*(previous - half), *(previous + half)])
        reach = self._reach(laser_id)
        if reach is not None:
            last, distance = reach
            return np.array([*(last - half - distance), *(last + half + distance)])
        return np.array([*(path.min(axis=0) - half), *(path.max(axis=0) + half)])

    def _track(self, image: np.ndarray, origin: np.ndarray, laser_id: int, path: np.ndarray,
               line: tuple[np.ndarray, np.ndarray] | None = None,
               refined: LineFreeSpot | None = None,
               excluded: list[np.ndarray] | None = None) -> SpotEstimate:
        """The full per-spot search; `refined`: a tracked spot's measurement without the
        line's light around its last position, as update() made it (a spot being acquired
        is measured so around the blob this search chooses); `excluded`: centres [px] of
        blobs that are not this diode's (another diode's spot): no blob within SAME_BLOB_PX
        or its own radius of one is a candidate."""
        s = self.settings
        lost = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
        box = np.round(self._search_box(laser_id, path) - np.tile(origin, 2)).astype(int)
        x0, y0 = max(box[0], 0), max(box[1], 0)
        x1, y1 = min(box[2], image.shape[1] - 1), min(box[3], image.shape[0] - 1)
        if x1 - x0 < 4 or y1 - y0 < 4:
            return lost
        window = image[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
        background = border_median(window)
        signal = window - background
        count, labels, stats, centroids = cv2.connectedComponentsWithStats(
            (signal > s.threshold).astype(np.uint8), connectivity=8)
        if count < 2:
            return lost
        # Every blob's centre, distance to the path and mass at once (label 0: background).
        centres = centroids[1:] + np.array([x0, y0]) + origin
        off_paths = distances_to_paths(centres, np.broadcast_to(path, (count - 1, *path.shape)))
        masses = np.bincount(labels.ravel(), weights=signal.ravel(), minlength=count)[1:]
        previous = self.previous[laser_id]
        priors = np.ones(count - 1) if previous is None else np.exp(
            -np.sum((centres - previous) ** 2, axis=1) / (2 * s.prior_sigma_px**2))
        tolerance = self.tolerance_px[laser_id]
        radii = np.sqrt(stats[1:, cv2.CC_STAT_AREA] / np.pi)
        near_path = off_paths <= tolerance + 2 * radii
        for taken in excluded or []:
            near_path &= np.hypot(*(centres - taken).T) > np.maximum(SAME_BLOB_PX, radii)
        reach = self._reach(laser_id)
        if reach is not None:
            near_path &= np.hypot(*(centres - reach[0]).T) <= reach[1]
        if np.isfinite(self.max_elongation):   # discovery's tracker takes any shape
            near_path[near_path] = [
                self._spot_like(image, origin, np.array(peak), background, line,
                                own_light(window, labels, label, peak, (x0, y0),
                                          s.window_px // 2))
                for label, peak in zip((np.flatnonzero(near_path) + 1).tolist(),
                                       self._peaks(signal, labels, near_path, (x0, y0)),
                                       strict=True)]
        # A blob far heavier than a candidate may own it as a grain of its halo, unless it
        # lies at the laser line, whose light is no halo.
        owners = masses * HALO_GRAIN_SHARE > masses[near_path].min(initial=np.inf)
        if line is not None:
            owners[owners] = [not self._near_line(origin, np.array(peak), line)
                              for peak in self._peaks(signal, labels, owners, (x0, y0))]
        near_path &= ~halo_grains(near_path, owners, centres, masses, radii)
        candidates = [(bool(off_paths[k] <= tolerance), float(masses[k] * priors[k]),
                       float(masses[k]), k + 1, centres[k]) for k in np.flatnonzero(near_path)]
        if not candidates:
            return lost
        # A blob centred on the path comes first: a long stretch of laser line crossing the
        # path outweighs the spot, but its centroid lies off the path.
        candidates.sort(key=lambda c: (c[0], c[1]), reverse=True)
        on_path, _, mass, label, centre = candidates[0]
        flags = 0
        if any(c[0] == on_path and c[2] >= s.min_competitor * mass for c in candidates[1:]):
            flags |= REFLECTION_SUSPECTED
        fixed = self.aperture_px[laser_id] > 0
        radius = self.aperture_px[laser_id] if fixed else \
            max(s.aperture_factor * np.sqrt(stats[label, cv2.CC_STAT_AREA] / np.pi), 3.0)
        # The background just outside a fixed aperture (as `spot_windows` takes it); a
        # clipped centroid's floor.
        ring = aperture_ring(radius, s.window_px)
        bounds = spot_window(image.shape, origin, centre, ring) if fixed else None
        if bounds is not None:
            floor = ring_median(np.ascontiguousarray(
                image[bounds[1]:bounds[3], bounds[0]:bounds[2]]), ring, ring)
        else:
            floor = background + (0.0 if fixed else
                                  s.clip_fraction * float(signal[labels == label].max()))
        for _ in range(FIXED_APERTURE_PASSES if fixed else 2):
            region = self._aperture(image, origin, centre, radius, floor)
            if region is None:
                return lost
            xs, ys, weights, raw = region
            total = float(weights.sum())
            if total <= 0:
                return lost
            settled = np.array([np.sum(weights * xs), np.sum(weights * ys)]) / total
            moved, centre = float(np.hypot(*(settled - centre))), settled
            if fixed and moved < FIXED_APERTURE_SETTLED_PX:
                break
        peak = float(raw.max())
        variance = np.clip(raw, 0, None) + s.read_noise**2
        distances = np.hypot(xs - centre[0], ys - centre[1])
        bounds = spot_window(image.shape, origin, centre, s.window_px)
        around = window if bounds is None else image[bounds[1]:bounds[3], bounds[0]:bounds[2]]
        step = step_sigma_px(background_step(np.ascontiguousarray(around), s.read_noise),
                             float(distances[weights > 0].sum()), total)
        sigma = float(np.sqrt(np.sum(variance * distances**2) / 2 / total**2 + step**2))
        # The laser line's light pulls a spot it passes towards itself, even off its path:
        # such a spot is measured again with the line's light subtracted.
        if previous is None and line is not None:
            refined = settled_line_free_centre(image, origin, centre, line, s)
            if refined is not None and line_bends(refined):
                return lost
        if refined is not None and \
                refined.line_edge_px - float(np.hypot(*(centre - refined.centre))) > radius:
            # The line's light above the threshold lies beyond the aperture about the
            # centroid (the line-free centre's distance to it, less how far the centroid lies
            # from that centre: a centroid the line's light pulled is nearer to it): the
            # centroid holds little of it and is the less noisy of the two (docs/tracking.md).
            refined = None
        beside_line_peak, on_line, light = np.nan, False, mass
        if refined is not None:
            light = np.nan   # the blob's light can be the line's
            if not np.isfinite(refined.centre).all():
                return lost   # the blob was the line's light alone, or hides the spot
            # The blob's brightest pixel can be the line's: the spot is told by its own light.
            centre, beside_line_peak = refined.centre, refined.beside_line_peak
            on_line = bool(refined.clearance_px < 0)
            if on_line:
                sigma = max(sigma, ON_LINE_SIGMA_PX[1], refined.line_sigma_px)
            sigma = line_free_sigma_px(sigma, refined)
        if distance_to_path(centre, path) > self.tolerance_px[laser_id]:
            return SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST | OFF_PATH)
        if peak >= s.saturation_level:
            flags |= SATURATED
        # A clipped centroid's speckle is judged with the frame's other spots (`_with_speckle`);
        # a centre measured without the line's light is not that centroid.
        clipped = not fixed and refined is None
        return SpotEstimate(laser_id, float(centre[0]), float(centre[1]), sigma, peak, flags,
                            beside_line_peak, on_line, light, radius if clipped else 0.0,
                            floor if clipped else np.nan)

    @staticmethod
    def _peaks(signal: np.ndarray, labels: np.ndarray, chosen: np.ndarray,
               corner: tuple[int, int]) -> list[tuple[float, float]]:
        """Region (x, y) of the brightest pixel of each `chosen` blob (labels 1…) of a window
        whose top-left region pixel is `corner`."""
        indices = (np.flatnonzero(chosen) + 1).tolist()
        if not indices:
            return []
        return [(corner[0] + x, corner[1] + y)
                for y, x in maximum_position(signal, labels, indices)]

    def _spot_like(self, image: np.ndarray, origin: np.ndarray, peak: np.ndarray,
                   background: float, line: tuple[np.ndarray, np.ndarray] | None,
                   own: tuple[np.ndarray, np.ndarray]) -> bool:
        """Whether the light around a blob's brightest pixel `peak` (region px) can be a
        spot: no more elongated than `max_elongation` (`kernels.light_elongation` within half
        a window, above the threshold over the search's `background`), neither all the light
        there nor the blob's `own` light alone (`own_light`: a stripe beside a spot is round
        with the spot's light), unless the laser line runs near it (`_near_line`: a spot on
        or beside the line is the line-free measurement's to judge)."""
        if line is not None and self._near_line(origin, peak, line):
            return True
        reach = self.settings.window_px / 2
        threshold = self.settings.threshold
        own_window, own_peak = own
        return max(light_elongation(image, float(peak[0]), float(peak[1]), reach, background,
                                    threshold),
                   light_elongation(own_window, float(own_peak[0]), float(own_peak[1]), reach,
                                    background, threshold)) <= self.max_elongation

    def _near_line(self, origin: np.ndarray, point: np.ndarray,
                   line: tuple[np.ndarray, np.ndarray]) -> bool:
        """Whether the laser line (rows, columns [px]) runs within three quarters of a window
        of `point` (region px): a spot's light reaches that far."""
        x, y = point + origin
        line_x = np.interp(y, line[0], line[1], left=np.nan, right=np.nan)
        return bool(abs(line_x - x) <= 0.75 * self.settings.window_px)

    @staticmethod
    def _aperture(image: np.ndarray, origin: np.ndarray, centre: np.ndarray, radius: float,
                  background: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Full-frame pixel coordinates, background-subtracted weights and raw values of the
        pixels within `radius` of `centre`; None if the aperture leaves the image."""
        half = int(np.ceil(radius)) + 1
        cx, cy = np.round(centre - origin).astype(int)
        x0, y0, x1, y1 = cx - half, cy - half, cx + half, cy + half
        if x0 < 0 or y0 < 0 or x1 >= image.shape[1] or y1 >= image.shape[0]:
            return None
        raw = image[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
        columns = np.arange(x0, x1 + 1) + origin[0]
        rows = np.arange(y0, y1 + 1) + origin[1]
        inside = (columns[None] - centre[0]) ** 2 + (rows[:, None] - centre[1]) ** 2 <= radius**2
        ys, xs = np.nonzero(inside)
        return (columns[xs], rows[ys], np.clip(raw[inside] - background, 0, None),
                raw[inside])


@dataclass(frozen=True)
class LineFreeSpot:
    """A spot measured with the laser line's light taken away (`spot_without_line`).

    `centre` [px] and `along` (unit vector of the line's direction) are in the caller's frame;
    `clearance_px` is the gap between the spot's edge and the line's edge at the threshold
    (negative where the two overlap, and there the centre is uncertain across the line: a
    saturated line hides the spot's light on its side; along the line it is not). Both are
    NaN where the line's light was all there was (no spot) or the spot's centre is hidden.
    `line_sigma_px` is the centre's uncertainty from the line's speckle left in the spot's
    light (`line_speckle_sigma_px`); `symmetry_sigma_px` its uncertainty per axis from how
    sharply its symmetry falls off across the line and along it (`symmetry_spreads`, the
    root mean square of the two), which holds every noise in the spot's light.
    `beside_line_peak` is the brightest of the spot's own light beside the line's band (its
    half width at the threshold) [grey levels over the background]: on the band, what the
    line's profile leaves of the line's own light (its speckle, a widening) is as bright as a
    spot's, beside it little is; a spot within the band, or all saturated there, has none.
    `line_deficit` is the most the known light within half a window of the centre falls
    below the line's profile [grey levels]: a spot only adds light, a line that bends or
    shifts there leaves a trough beside its crest (LINE_BEND_SHARE).
    `line_edge_px` is the distance from the centre to the line's edge at the threshold [px]
    (NaN with the centre)."""

    centre: np.ndarray
    along: np.ndarray
    clearance_px: float
    line_sigma_px: float = 0.0
    symmetry_sigma_px: float = 0.0
    beside_line_peak: float = np.nan
    line_deficit: float = np.nan
    line_edge_px: float = np.nan


def own_light(window: np.ndarray, labels: np.ndarray, label: int, peak: tuple[float, float],
              corner: tuple[int, int], half: int) -> tuple[np.ndarray, np.ndarray]:
    """The light of blob `label` alone (`labels` of a search `window` whose top-left region
    pixel is `corner`) within `half` px of its brightest pixel `peak` (region px), other
    pixels at 0, and that pixel's place in it."""
    x, y = int(peak[0]) - corner[0], int(peak[1]) - corner[1]
    x0, y0 = max(x - half, 0), max(y - half, 0)
    around = window[y0:y + half + 1, x0:x + half + 1]
    return (np.where(labels[y0:y + half + 1, x0:x + half + 1] == label, around, 0),
            np.array([x - x0, y - y0]))


def line_free_sigma_px(sigma_px: float, found: LineFreeSpot) -> float:
    """A spot's σ [px per axis] measured without the laser line's light: `sigma_px` and the
    uncertainty of its centre of symmetry (`LineFreeSpot.symmetry_sigma_px`) in quadrature."""
    return float(np.hypot(sigma_px, found.symmetry_sigma_px))


def line_bends(found: LineFreeSpot) -> bool:
    """Whether the laser line bends where a spot not yet acquired was found on it: the light
    about it falls below the line's profile by more than LINE_BEND_SHARE of its own peak
    beside the line."""
    return found.line_deficit > LINE_BEND_SHARE * found.beside_line_peak


def line_free_centre(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                     line: tuple[np.ndarray, np.ndarray], s: SpotSettings) -> LineFreeSpot | None:
    """The spot in the window around `centre` (full-frame px; moved inside the image where
    the spot lies within a window of its edge) with the laser line's light subtracted
    (`spot_without_line`) on the rows between the line's ends; None where the line
    (full-frame rows, ascending, and columns) does not cross the window or the image is
    smaller than a window."""
    window = spot_window_inside(image.shape, origin, centre, s.window_px)
    if window is None:
        return None
    x0, y0, _, y1 = window
    rows = np.arange(y0, y1) + origin[1]
    # Only the rows the line was measured on: across a gap it need not be straight.
    measured = np.round(line[0])
    nearest = measured[np.minimum(np.searchsorted(measured, rows), len(measured) - 1)]
    line_x = np.where(nearest == rows, np.interp(rows, line[0], line[1]), np.nan) - \
        origin[0] - x0
    if not np.any(np.abs(line_x - s.window_px) <= 1.5 * s.window_px):
        return None
    # Beyond its ends (the container's rim) the line has no light to take away: a spot
    # there keeps all of its own.
    span = (int(measured[0] - origin[1] - y0), int(measured[-1] - origin[1] - y0))
    return window_without_line(image, origin, window, line_x, centre, s, span)


def settled_line_free_centre(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                             line: tuple[np.ndarray, np.ndarray], s: SpotSettings,
                             rounds: int = 3) -> LineFreeSpot | None:
    """`line_free_centre`, measured again from where it lands until that moves less than a
    quarter pixel (at most `rounds` times): from a start far from the spot (a blob's centre
    on the line, a point of its path) the window's rows and its brightest patch are not the
    spot's, and one measurement landed up to 6 px off; the next, centred on it, is right.
    A centre that moved more than HIDDEN_SYMMETRY_PX in the last round is not known (a NaN
    centre, as for a hidden one): the development stills' one wrong spot on the line (rig
    7113, 2.1 px off, σ 0.13 px) was the third of three measurements that each moved 10-18
    px, its centre of symmetry at the edge of the search, the mismatch still falling towards
    the spot's own centre. Two centres a fraction of a pixel apart that the rounds alternate
    between are the spot's (a speckled spot beside the line: 0.6 px apart, 1.5-2 px off)."""
    refined, moved = None, 0.0
    for _ in range(rounds):
        refined = line_free_centre(image, origin, centre, line, s)
        if refined is None or not np.isfinite(refined.centre).all():
            return refined
        moved = float(np.hypot(*(refined.centre - centre)))
        if moved < 0.25:
            return refined
        centre = refined.centre
    if refined is None or moved <= HIDDEN_SYMMETRY_PX:
        return refined
    return LineFreeSpot(np.full(2, np.nan), refined.along, np.nan)


def window_without_line(image: np.ndarray, origin: np.ndarray,
                        window: tuple[int, int, int, int], line_x: np.ndarray,
                        centre: np.ndarray, s: SpotSettings,
                        line_span: tuple[int, int] | None = None) -> LineFreeSpot | None:
    """`spot_without_line` on a window of the region (`spot_window` bounds; `line_x` in
    window columns per window row, the line on the window rows `line_span`, first and last,
    or on every row), started at `centre`, in full-frame px."""
    x0, y0, x1, y1 = window
    corner = (x0 + int(origin[0]), y0 + int(origin[1])) if s.chroma_blocks else None
    local = spot_without_line(image[y0:y1, x0:x1].astype(np.float32), line_x,
                              centre - origin - (x0, y0), s, line_span, corner)
    if local is None:
        return None
    return replace(local, centre=local.centre + origin + (x0, y0))


def reflection_normals(normal: np.ndarray, spread_deg: float) -> np.ndarray:
    """A unit normal and eight more `spread_deg` from it, every 45° about it (9×3)."""
    across = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    other = np.cross(normal, across)
    angles = np.radians(45.0) * np.arange(8)
    spread = np.radians(spread_deg)
    tilted = np.cos(spread) * normal + np.sin(spread) * (
        np.cos(angles)[:, None] * across + np.sin(angles)[:, None] * other)
    return np.vstack([normal, tilted])


def joined_light(image: np.ndarray, origin: np.ndarray, spot_px: np.ndarray,
                 others_px: np.ndarray, s: SpotSettings) -> bool:
    """Whether the light above the threshold joined to a spot's centre (full-frame px) comes
    within REFLECTION_REACH_PX of any of the other points (K×2 full-frame px) no farther
    than a window (`window_px`) from it: over the box holding them and half a window around
    them, the background being the median of its border. The spot's light is every blob
    that comes within REFLECTION_REACH_PX of its centre: the centroid of a spot and its
    reflection joined by a faint neck may lie on no lit pixel."""
    others_px = others_px[np.hypot(*(others_px - spot_px).T) <= s.window_px]
    if not len(others_px):
        return False
    margin = s.window_px // 2
    low = np.floor(np.minimum(spot_px, others_px.min(axis=0)) - origin).astype(int) - margin
    high = np.ceil(np.maximum(spot_px, others_px.max(axis=0)) - origin).astype(int) + \
        margin + 1
    low, high = np.maximum(low, 0), np.minimum(high, [image.shape[1], image.shape[0]])
    box = image[low[1]:high[1], low[0]:high[0]].astype(np.float32)
    _, labels = cv2.connectedComponents((box - border_median(box) > s.threshold)
                                        .astype(np.uint8))
    column, row = spot_px - origin - low
    rows, columns = np.nonzero(labels)
    near = np.hypot(columns - column, rows - row) <= REFLECTION_REACH_PX
    own = np.isin(labels[rows, columns], labels[rows[near], columns[near]])
    rows, columns = rows[own], columns[own]
    targets = others_px - origin - low
    return bool((np.hypot(columns[:, None] - targets[:, 0], rows[:, None] - targets[:, 1])
                 <= REFLECTION_REACH_PX).any())


def spot_window_inside(shape: tuple[int, ...], offset: np.ndarray, centre: np.ndarray,
                       half: int) -> tuple[int, int, int, int] | None:
    """`spot_window`, moved inside the image where it would leave it (the centre is then off
    the window's middle), or None where the image is smaller than the window."""
    size = 2 * half + 1
    if shape[0] < size or shape[1] < size:
        return None
    cx, cy = np.round(centre - offset).astype(int)
    x0 = int(np.clip(cx - half, 0, shape[1] - size))
    y0 = int(np.clip(cy - half, 0, shape[0] - size))
    return x0, y0, x0 + size, y0 + size


def spot_window(shape: tuple[int, ...], offset: np.ndarray, centre: np.ndarray, half: int
                ) -> tuple[int, int, int, int] | None:
    """Region-pixel bounds (x0, y0, x1, y1; end exclusive) of the window of half size `half`
    around a full-frame centre, or None where it would leave the image."""
    cx, cy = np.round(centre - offset).astype(int)
    x0, y0, x1, y1 = cx - half, cy - half, cx + half + 1, cy + half + 1
    if x0 < 0 or y0 < 0 or x1 > shape[1] or y1 > shape[0]:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def spot_without_line(window: np.ndarray, line_x: np.ndarray, spot: np.ndarray,
                      s: SpotSettings, line_span: tuple[int, int] | None = None,
                      block_corner_px: tuple[int, int] | None = None) -> LineFreeSpot | None:
    """A spot's centre [window px] with the laser line's light taken away, the line's
    direction and the clearance between the two; None when the line does not reach enough of
    the window's rows, a NaN centre when no spot is left (nothing LINE_SPECKLE_PEAK times
    the line's speckle, and above the threshold, on the line or beside it) or where its
    centre cannot be told (a saturated line hides its mirror half: HIDDEN_SYMMETRY_SHARE; or
    its symmetry has a flat side: HIDDEN_CENTRE_RISE). The centre's own σ from its symmetry
    is `symmetry_sigma_px` (`symmetry_spreads`).

    `line_x[r]` is the line's centre column on window row r (NaN where unknown); the line
    lies on the rows `line_span` (first and last; None: every row) and a straight line through
    it on the rows beyond half a window from the spot is used. The line's
    cross profile (signal against the column's offset from that line, in PROFILE_STEP_PX
    bins) is the median over its rows that lie beyond half a window from the spot, and is
    subtracted from every one of its rows, the spot's included: a spot on the line keeps its
    own light and loses the line's, a spot beside it no longer leans towards it. A saturated
    pixel the line lights holds an unknown share of the spot's light, so the centre is not a
    centroid but the point about which what is left is most nearly symmetric, over the known
    pixels within half a window (SYMMETRY_REACH_SHARE of one for a spot saturated beside the
    line; `kernels.symmetric_centre`): a spot's own light is point-symmetric (a Gaussian, or
    an ellipse on a tilted surface), the line's ragged remainder is not. In an image with
    chroma blocks (`block_corner_px`: the window's top-left pixel, full-frame) the pixels
    that share a block with a saturated one the line lights hold at least what is left
    there (`chroma.pixel_states`): the camera averaged the block after the sensor clipped.
    """
    rows, columns = np.indices(window.shape)
    background = border_median(window)
    reach = s.window_px // 2
    first_row, last_row = line_span or (0, window.shape[0] - 1)
    # The line's own centre is pulled towards a spot on its rows: a straight line through
    # its centres on the rows away from the spot stands for it on every row.
    row_index = np.arange(len(line_x))
    usable = np.isfinite(line_x) & (np.abs(row_index - spot[1]) > reach)
    if usable.sum() < 4:
        return None
    fit_rows, fit_columns = row_index[usable], line_x[usable]
    centred = fit_rows - fit_rows.mean()
    slope = float(centred @ (fit_columns - fit_columns.mean()) / (centred @ centred))
    intercept = float(fit_columns.mean() - slope * fit_rows.mean())
    left, unknown, line_half_width, profile_pixels = remove_line(
        window, background, slope, intercept, spot[1], reach, PROFILE_STEP_PX, s.threshold,
        s.saturation_level, first_row, last_row)
    if profile_pixels < 3 * (2 * reach + 1):
        return None
    states = pixel_states(unknown, block_corner_px)
    # The line's speckle leaves light of its own within the line's band: what it leaves on
    # the profile's rows says how much.
    offsets = np.asarray(columns - intercept - slope * rows, dtype=float)
    lit = (rows >= first_row) & (rows <= last_row)
    band = (np.abs(offsets) <= line_half_width) & lit
    away = ~unknown & (np.abs(rows - spot[1]) > reach) & lit
    on_line = band & away
    speckle = 1.4826 * float(np.median(np.abs(left[on_line]))) if on_line.any() else 0.0
    # Beside its band the line's speckled wings, dim on average, leave grains as bright as
    # a dim spot: there each offset from the line has a floor of its own speckle.
    floor = np.where(band, LINE_SPECKLE_PEAK * speckle, LINE_SPECKLE_PEAK *
                     line_wing_speckle(left, offsets, away, reach))
    floor = np.maximum(np.where(lit, floor, 0.0), s.threshold)
    # Two starts: `spot`, and the brightest 5×5 patch of what is left within half a window
    # of it (not another spot's or a reflection's farther away), where that is not already
    # within the search around `spot`.
    patch = cv2.blur(left.astype(np.float32), (5, 5))
    patch[(columns - spot[0]) ** 2 + (rows - spot[1]) ** 2 > reach**2] = -np.inf
    row, column = np.unravel_index(int(np.argmax(patch)), patch.shape)
    # Only the light joined to the spot (through the line's unknown pixels, too): a
    # neighbouring spot's would break the symmetry.
    _, labels = cv2.connectedComponents(((left > s.threshold) | unknown).astype(np.uint8))
    joined = cv2.dilate((labels == labels[row, column]).astype(np.uint8), np.ones((5, 5)))
    # Its troughs too (line_deficit), but not on a line's fading end within the window: the
    # profile is its full light, which the end rows do not hold.
    ends = ((rows > last_row - LINE_END_FADING_ROWS) & (last_row < window.shape[0] - 1)) | \
        ((rows < first_row + LINE_END_FADING_ROWS) & (first_row > 0))
    everywhere = np.where(ends, 0.0, left)
    left = np.where(joined > 0, left, 0.0)
    starts = [(float(spot[0]), float(spot[1]))]
    if np.hypot(column - spot[0], row - spot[1]) > SYMMETRY_SEARCH_PX / 2:
        starts.append((float(column), float(row)))
    # A spot saturated beside the line is wide: its edges lie beyond half a window.
    saturated = int(np.count_nonzero((window >= s.saturation_level) & ~unknown & (joined > 0))
                    ) >= SATURATED_BESIDE_LINE_PX
    symmetry_reach = int(SYMMETRY_REACH_SHARE * s.window_px) if saturated else reach
    x, y, mismatch = min((symmetric_centre(left, states, x, y, symmetry_reach, s.threshold,
                                           SYMMETRY_SEARCH_PX, SYMMETRY_PAIRS)
                          for x, y in starts), key=lambda found: found[2])
    # A spot centred within the saturated line's band that does not reach across it has its
    # mirror half hidden: its own centre has too few pairs, and the best centre that has
    # enough is off by a spot's radius. Where a centre with fewer pairs is far more nearly
    # symmetric and elsewhere, the spot's centre is not known.
    hidden_x, hidden_y, hidden_mismatch = min(
        (symmetric_centre(left, states, x, y, symmetry_reach, s.threshold, SYMMETRY_SEARCH_PX,
                          HIDDEN_SYMMETRY_PAIRS) for x, y in starts), key=lambda found: found[2])
    centre = np.array([x, y])
    near = (columns - x) ** 2 + (rows - y) ** 2 <= reach**2
    norm = float(np.hypot(slope, 1.0))
    along = np.array([slope, 1.0]) / norm
    hidden = hidden_mismatch < HIDDEN_SYMMETRY_SHARE * mismatch and \
        np.hypot(hidden_x - x, hidden_y - y) > HIDDEN_SYMMETRY_PX
    if not np.isfinite(mismatch) or hidden or not (left[near] > floor[near]).any():
        return LineFreeSpot(np.full(2, np.nan), along, np.nan)
    across = np.array([1.0, -slope]) / norm
    spreads = symmetry_spreads(left, states, centre, (across, along), symmetry_reach,
                               s.threshold)
    if min(rise for _, rise in spreads) < HIDDEN_CENTRE_RISE:
        return LineFreeSpot(np.full(2, np.nan), along, np.nan)
    # Clearance: the spot's reach on its side away from the line (where the line's light is
    # not) and the line's half width at the threshold, against their centres' distance.
    to_line = (intercept + slope * centre[1] - centre[0]) / norm
    spot_rows, spot_columns = np.nonzero(near & (left > s.threshold))
    spot_pixels = np.column_stack([spot_columns, spot_rows])
    distance2 = np.asarray((columns - x) ** 2 + (rows - y) ** 2)
    sigma = line_speckle_sigma_px(speckle, distance2[near & band & ~unknown],
                                  float(np.clip(left[near & ~unknown], 0, None).sum()))
    return LineFreeSpot(centre, along, _clearance(spot_pixels, centre, to_line * across, along,
                                                  line_half_width / norm), sigma,
                        float(np.sqrt(np.mean([sigma**2 for sigma, _ in spreads]))),
                        float(left[near & ~band & ~unknown].max(initial=0.0)),
                        -float(everywhere[near & ~unknown].min(initial=0.0)),
                        abs(to_line) - line_half_width / norm)


def symmetry_spreads(left: np.ndarray, states: np.ndarray, centre: np.ndarray,
                     directions: tuple[np.ndarray, ...], reach: int, threshold: float
                     ) -> list[tuple[float, float]]:
    """How sharply a spot's symmetry falls off along each unit vector of `directions` from
    its centre of symmetry (`kernels.symmetric_centre`, `centre` in window px): the mismatch
    M0 there (N pairs) rises to M_h, the lower of the two at SYMMETRY_STEP_PX h either way.
    Per direction: the centre's uncertainty σ [px] that way, from least squares over pairs
    whose difference has the variance M0, SYMMETRY_NOISE_PIXELS pixels to each draw of the
    noise: σ² = 2·M0·h²·SYMMETRY_NOISE_PIXELS / (N·(M_h − M0)); and the rise (M_h − M0) / M0,
    which a side the saturated line hides leaves small (HIDDEN_CENTRE_RISE). (inf, 0) where a
    step lowers the mismatch (no least mismatch that way); (0, inf) where it is exactly
    symmetric."""
    at_centre, pairs = symmetry_mismatch(left, states, float(centre[0]), float(centre[1]),
                                         reach, threshold, 1)
    spreads = []
    for direction in directions:
        step = SYMMETRY_STEP_PX * direction
        stepped = min(symmetry_mismatch(left, states, float(centre[0] + sign * step[0]),
                                        float(centre[1] + sign * step[1]), reach, threshold,
                                        1)[0]
                      for sign in (-1.0, 1.0))
        if pairs == 0 or stepped <= at_centre:
            spreads.append((np.inf, 0.0))
        elif at_centre == 0:
            spreads.append((0.0, np.inf))
        else:
            spreads.append((float(np.sqrt(2 * at_centre * SYMMETRY_STEP_PX**2 *
                                          SYMMETRY_NOISE_PIXELS /
                                          (pairs * (stepped - at_centre)))),
                            float((stepped - at_centre) / at_centre)))
    return spreads


def line_wing_speckle(left: np.ndarray, offsets_px: np.ndarray, away: np.ndarray,
                      reach: int) -> np.ndarray:
    """Per pixel, the robust σ [grey levels] of what the laser line's profile leaves at that
    pixel's offset from the line (`offsets_px`, in 1 px bins up to `reach`; 0 beyond), over
    the pixels `away` from the spot: speckle multiplies the line's light, so its wings, dim
    on average, leave grains as bright as a spot's beside a bright line."""
    # Each pixel's bin 0..2·reach, and 2·reach + 1 beyond the reach (σ 0 there).
    bins = np.round(offsets_px).astype(int)
    index = np.where(np.abs(bins) <= reach, bins + reach, 2 * reach + 1)
    keys, values = index[away], np.abs(left[away])
    # The bins' medians at once: each bin's values sorted, their middle one or two taken.
    order = np.lexsort((values, keys))
    keys, values = keys[order], values[order]
    starts = np.searchsorted(keys, np.arange(2 * reach + 1))
    counts = np.searchsorted(keys, np.arange(2 * reach + 1), side="right") - starts
    lower = values[np.minimum(starts + (counts - 1) // 2, len(values) - 1)] if len(values) \
        else np.zeros(2 * reach + 1)
    upper = values[np.minimum(starts + counts // 2, len(values) - 1)] if len(values) \
        else np.zeros(2 * reach + 1)
    medians = np.where(counts % 2 == 1, lower, (lower + upper) / 2)
    per_bin = np.append(np.where(counts > 0, 1.4826 * medians, 0.0), 0.0)
    return per_bin[index]


def line_speckle_sigma_px(speckle: float, distance2_px2: np.ndarray, light: float) -> float:
    """The uncertainty [px] a spot's centre gets from the laser line's speckle left in its
    light where the line crosses it: the line's profile is a median, so each pixel of its
    band keeps its own speckle (robust σ `speckle`), which moves the centre of the spot's
    known `light` as noise moves a centroid, by the pixels' squared distances from it
    (`distance2_px2`). A saturated spot outshines it (about 0.1 px, ON_LINE_SIGMA_PX); a dim
    one under strong speckle is uncertain by a pixel or more. 0 where none of the spot's
    light is known (all saturated: its outline centres it)."""
    if light <= 0:
        return 0.0
    return float(speckle * np.sqrt(distance2_px2.sum() / 2) / light)


def _clearance(spot_pixels: np.ndarray, centre: np.ndarray, to_line: np.ndarray,
               along: np.ndarray, line_half_width_px: float) -> float:
    """Gap [px] between a spot's edge and the laser line's edge (negative: they overlap).

    `spot_pixels` (N×2) are the spot's pixels above the threshold, `to_line` the vector from
    its centre to the nearest point of the line's centre, `along` the line's unit direction.
    The spot's reach is taken on its side away from the line, where the line's light is not.
    """
    across = np.array([along[1], -along[0]])
    distance = float(abs(to_line @ across))
    away = -1.0 if to_line @ across > 0 else 1.0
    reach = float(np.max(away * ((spot_pixels - centre) @ across), initial=0.0))
    return distance - reach - line_half_width_px
