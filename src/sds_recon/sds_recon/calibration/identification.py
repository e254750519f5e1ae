"""Which blob is which diode's spot, over a whole series of known surfaces.

A diode's spots on known surfaces must all lie on one straight beam through its emitter. For
each diode, every blob that lies within a search cone around the nominal beam is a hypothesis
(the beam from the emitter through that blob's point on its surface); the hypothesis is
verified by predicting the spot on every other surface and counting the frames that have a
blob there. The best-supported hypothesis wins only if no other one, using other blobs, comes
close; blobs claimed by two diodes go to neither where the claims are alike. What is left is
a wall reflection or noise (seed Fig. 9a). A diode that cannot be identified unambiguously is
named with the reason, never assigned a doubtful blob.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sds_model.rig import Rig

from sds_recon.calibration.lasers import KnownSurface, surface_points


@dataclass(frozen=True)
class IdentificationSettings:
    """How wide to search and how strict to verify."""

    cone_deg: float = 3.0           # hypotheses within this angle of the nominal beam
    gate_mm: float = 1.0            # a predicted spot and its blob: at most this far (surface)
    min_frames: int = 3             # a diode needs its spot on this many surfaces at least
    min_share: float = 0.6          # ... and on this share of the surfaces it should hit
    ambiguity_margin: int = 1       # a rival this close in support makes a diode ambiguous


@dataclass(frozen=True)
class Identification:
    """Per diode, the blob index in each frame it was seen in; unidentified diodes with why;
    per frame the blobs no diode claimed (reflections, noise)."""

    assigned: dict[int, dict[int, int]]
    unidentified: dict[int, str]
    unclaimed: list[list[int]] = field(default_factory=list)


@dataclass(frozen=True)
class _Hypothesis:
    support: dict[int, int]     # frame → blob
    error_px2: float            # summed squared distance of the supporting blobs
    lean_rad: float = 0.0       # angle from the rig file's beam


def _predict(rig: Rig, emitter: np.ndarray, direction: np.ndarray,
             surfaces: list[KnownSurface]) -> tuple[np.ndarray, np.ndarray]:
    """Hits (F×3 mm) of one beam on each surface and their pixels (F×2)."""
    hits = np.array([s.intersect(emitter, direction[None])[0] for s in surfaces])
    return hits, rig.project(hits)


def _fit_direction(emitter: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Unit direction of the line from the emitter that best fits the points (moments)."""
    offsets = points - emitter
    direction = np.linalg.eigh(offsets.T @ offsets)[1][:, -1]
    return -direction if direction[2] > 0 else direction


def identify_spots(rig: Rig, surfaces: list[KnownSurface], blobs: list[np.ndarray],
                   settings: IdentificationSettings | None = None) -> Identification:
    """Assign blobs (per frame, N_k×2 px) to the rig's diodes over the frames' known surfaces."""
    s = settings or IdentificationSettings()
    gate_px = s.gate_mm * rig.surface_px_per_mm()
    radius = rig.container.radius_mm
    points = [surface_points(rig, b, surf) if len(b) else np.zeros((0, 3))
              for b, surf in zip(blobs, surfaces, strict=True)]
    ranked: dict[int, list[_Hypothesis]] = {}
    needed: dict[int, int] = {}
    unidentified: dict[int, str] = {}
    for diode in rig.diodes:
        hypotheses: dict[tuple[tuple[int, int], ...], _Hypothesis] = {}
        for frame_points in points:
            offsets = frame_points - diode.emitter_mm
            norms = np.linalg.norm(offsets, axis=1)
            cosine = offsets @ diode.direction / np.maximum(norms, 1e-9)
            for j in np.flatnonzero(cosine >= np.cos(np.radians(s.cone_deg))):
                direction = offsets[j] / norms[j]
                hypothesis = _verify(rig, diode.emitter_mm, direction, surfaces, blobs,
                                     gate_px)
                # Refine once through all supporting points, then verify again.
                if len(hypothesis.support) >= 2:
                    chosen = np.array([points[f][b] for f, b in hypothesis.support.items()])
                    hypothesis = _verify(rig, diode.emitter_mm,
                                         _fit_direction(diode.emitter_mm, chosen), surfaces,
                                         blobs, gate_px)
                final = _fit_direction(diode.emitter_mm, np.array(
                    [points[f][b] for f, b in hypothesis.support.items()])) \
                    if hypothesis.support else direction
                lean = float(np.arccos(np.clip(final @ diode.direction, -1.0, 1.0)))
                hypothesis = _Hypothesis(hypothesis.support, hypothesis.error_px2, lean)
                hypotheses[tuple(sorted(hypothesis.support.items()))] = hypothesis
        hits, _ = _predict(rig, diode.emitter_mm, diode.direction, surfaces)
        expected = int(np.sum(np.hypot(hits[:, 0], hits[:, 1]) < radius))
        needed[diode.laser_id] = max(s.min_frames, int(np.ceil(s.min_share * expected)))
        ranked[diode.laser_id] = sorted(hypotheses.values(),
                                        key=lambda h: _rank(h, gate_px, s.cone_deg))
    ranked = {i: [h for h in hs if len(h.support) >= needed[i]] or hs[:1]
              for i, hs in ranked.items()}
    rank = {i: [_rank(h, gate_px, s.cone_deg) for h in hs] for i, hs in ranked.items()}
    assigned = _assign(ranked, rank, needed, unidentified, s, len(surfaces))
    claimed = [{b for support in assigned.values() for f, b in support.items() if f == k}
               for k in range(len(blobs))]
    unclaimed = [[j for j in range(len(b)) if j not in claimed[k]] for k, b in enumerate(blobs)]
    return Identification(assigned, unidentified, unclaimed)


def _rank(hypothesis: _Hypothesis, gate_px: float, cone_deg: float) -> tuple[int, float]:
    """Most surfaces first, then the smallest mean squared distance (in gates) plus the
    squared lean from the rig file's beam (in cones): where the surfaces cannot tell two
    beams apart (a diode near the tilt axis), the rig file's direction decides."""
    count = len(hypothesis.support)
    return -count, (hypothesis.error_px2 / max(count, 1) / gate_px**2
                    + (hypothesis.lean_rad / np.radians(cone_deg)) ** 2)


def _assign(ranked: dict[int, list[_Hypothesis]], rank: dict[int, list[tuple[int, float]]],
            needed: dict[int, int], unidentified: dict[int, str],
            s: IdentificationSettings, frames: int) -> dict[int, dict[int, int]]:
    """One hypothesis per diode, no blob used twice: the diodes whose best beam is most
    certain choose first; hypotheses through blobs already taken are out. A diode whose best
    remaining beam has a rival almost as well supported, through blobs that no other diode's
    best beam explains, is ambiguous."""
    first_choice = {i: set(hs[0].support.items()) for i, hs in ranked.items() if hs}
    taken: set[tuple[int, int]] = set()
    assigned: dict[int, dict[int, int]] = {}
    pending = set(ranked)
    while pending:
        options = {i: [k for k, h in enumerate(ranked[i]) if not taken & set(h.support.items())]
                   for i in pending}
        laser_id = min(pending, key=lambda i: rank[i][options[i][0]] if options[i]
                       else (1, 0.0))
        pending.discard(laser_id)
        choices = [ranked[laser_id][k] for k in options[laser_id]]
        if not choices or len(choices[0].support) < needed[laser_id]:
            seen = len(choices[0].support) if choices else 0
            unidentified[laser_id] = (f"no consistent beam: at most {seen} of {frames} "
                                      f"surfaces agree ({needed[laser_id]} needed)")
            continue
        winner = choices[0]
        others = set().union(*(c for i, c in first_choice.items() if i != laser_id))
        rival = next((h for h in choices[1:] if _conflicts(winner, h)
                      and not set(h.support.items()) - set(winner.support.items()) <= others),
                     None)
        if rival is not None and len(rival.support) >= len(winner.support) - s.ambiguity_margin:
            unidentified[laser_id] = (
                f"ambiguous: two beams fit, on {len(winner.support)} and {len(rival.support)} "
                "surfaces, through different blobs")
            continue
        assigned[laser_id] = dict(winner.support)
        taken |= set(winner.support.items())
    return assigned


def _verify(rig: Rig, emitter: np.ndarray, direction: np.ndarray,
            surfaces: list[KnownSurface], blobs: list[np.ndarray],
            gate_px: float) -> _Hypothesis:
    """The frames where a blob lies within the gate of the beam's predicted spot."""
    _, predicted = _predict(rig, emitter, direction, surfaces)
    support, error = {}, 0.0
    for k, (pixel, frame_blobs) in enumerate(zip(predicted, blobs, strict=True)):
        if not np.isfinite(pixel).all() or len(frame_blobs) == 0:
            continue
        distance = np.linalg.norm(frame_blobs - pixel, axis=1)
        nearest = int(np.argmin(distance))
        if distance[nearest] <= gate_px:
            support[k] = nearest
            error += float(distance[nearest] ** 2)
    return _Hypothesis(support, error)


def _conflicts(a: _Hypothesis, b: _Hypothesis) -> bool:
    """True if the hypotheses use different blobs in a frame both have."""
    return any(f in b.support and b.support[f] != blob for f, blob in a.support.items())
