"""Sequences of the simulated microscope's renderer with their truth: where the tracker is designed.

The tip tracker (:mod:`stickslip.vision.track`) is designed, and its decision rules
calibrated, on these frames only: the renderer of ``simcam://``
(:class:`stickslip.sim.camera.SimScene`: a cone with a rounded apex, Gaussian defocus,
bright field or SEM edge contrast, a smooth substrate with dust, Poisson noise) with the
needle placed directly, not through the arm. The second renderer
(``tests/support/vision_peer.py``) is the check it is never tuned to.

The conditions are issue 30's (tip widths 3 to 20 px, blur up to sigma 3 px, 40 to 400
photons a pixel, small turns, image drift, frames with the tip out of the field,
occluded or far out of focus), with this module's own motion: an arm's moves (glides of
up to 12 px a frame, holds, jumps of up to 40 px), a needle that turns by a few degrees
about a point far up its shaft, a substrate drifting at 0.05 px a frame plus a random
walk, a blur that wanders.
"""

from __future__ import annotations

import functools
import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from stickslip.sim.camera import Droplet, Flake, LobedParticle, SimCamSettings, SimScene

__all__ = ["OwnFrame", "OwnSequence", "own_sequence", "own_benchmark", "lobed_benchmark", "flake_benchmark",
           "round_benchmark", "droplet_benchmark", "micrograph", "micrograph_benchmark",
           "micrograph_sequence", "KINDS", "MICROGRAPHS"]

KINDS = ("visible", "out", "occluded", "defocused")

EDGE_IN = 10.0
"""A visible tip stays at least this far inside the field, px."""

EDGE_IN_LOBED = 4.0
"""With lobed debris, a visible tip comes this close to the field's edge, px."""


@dataclass(frozen=True)
class OwnFrame:
    """One frame and its truth: the tip (px, x right, y down), what the frame is, the blur (sigma, px)."""

    image: NDArray[np.float64]
    tip: tuple[float, float]
    kind: str
    blur: float
    cause: str = ""
    """What the lobed mode did to the frame: ``lobed`` (a lobed grain over the tip), ``edge``;
    the flake mode: ``flake`` (a flake stuck on the tip); the round mode: ``bead`` (a bead
    stuck on the tip), ``shaft-edge`` (the tip near the edge its shaft leaves by), ``bead-edge``
    (both); the droplet mode: ``droplet`` (a visible tip seen through a droplet)."""


@dataclass(frozen=True)
class OwnSequence:
    """Frames of one needle, look and noise."""

    frames: list[OwnFrame]
    width_px: float
    look: str
    photons: float


def own_sequence(seed: int, n: int = 40, size: int = 256, width_px: float | None = None, look: str | None = None,
                 photons: float | None = None, max_blur: float = 3.0, events: bool = True,
                 event_rate: float = 0.08, lobed_rate: float = 0.0, flake_rate: float = 0.0,
                 round_rate: float = 0.0, droplet_rate: float = 0.0,
                 ground: NDArray[np.float64] | None = None, defocus: str = "gaussian") -> OwnSequence:
    """``n`` frames of one needle moving in a ``size`` x ``size`` field, with the truth.

    ``width_px`` (default drawn in 3..20) is the apex's diameter, ``photons`` (default
    log-uniform in 40..400) the count at full brightness; ``look`` optical or sem (drawn).
    With ``events``, a frame starts an event (the tip out of the field, under a particle,
    far out of focus) with probability ``event_rate``, for 1 to 4 frames.
    With ``lobed_rate`` > 0 (the lobed mode, :class:`_Extras`), a frame without such an
    event starts another with that probability: a lobed grain over the tip, or the tip
    4 to 12 px inside the field's edge; the tip then roams to 4 px of the edge. Its draws
    come from a stream of their own: the motion and the other events stay as without it.
    With ``flake_rate`` > 0 (the flake mode, :class:`_Flakes`), a visible frame untouched
    by the other events starts, with that probability, a flake stuck on the tip for 1 to 4
    frames (its own stream too).
    With ``round_rate`` > 0 (the round mode, :class:`_Beads`), the needle ends in a blunt
    paraboloid (apex radius of curvature ``width_px / 2``) instead of a cone's cap, and a
    frame untouched by the other events starts, with that probability, a round opaque
    bead stuck on the tip, or the tip held near the edge its shaft leaves by, with or
    without a bead (its own stream too).
    With ``droplet_rate`` > 0 (the droplet mode, :class:`_Drops`), a bright-field frame
    untouched by the other events starts, with that probability, a transparent droplet
    clinging to the tip for 1 to 4 frames: the tip stays visible, seen through it,
    displaced and magnified (its own stream too).
    With ``ground`` (the micrograph mode, :func:`micrograph`), the substrate is a crop of that
    real micrograph (:func:`_ground`) instead of the simulator's smooth texture with dust; every
    other draw stays as without it.
    With ``defocus="disc"`` the needle's blur is geometric optics' blur circle of the same variance
    (:func:`stickslip.sim.camera.defocus_kernel`, radius ``2 sigma`` softened by a 0.5 px rim) instead of the
    Gaussian; every draw stays as without it (the blur's truth is still the Gaussian's sigma).
    """
    rng = np.random.default_rng([seed, 31337])
    look = look or ("optical", "sem")[int(rng.integers(0, 2))]
    W = float(width_px if width_px is not None else rng.uniform(3.0, 20.0))
    ph = float(photons if photons is not None else math.exp(rng.uniform(math.log(40.0), math.log(400.0))))
    taper = math.radians(float(rng.uniform(4.0, 15.0)))
    scene = SimScene(SimCamSettings(look=look, width=size, height=size, photons=ph, seed=int(seed) + 1,
                                    tip_radius_m=0.5 * W * 0.5e-6, taper=taper, pixel_size_m=0.5e-6,
                                    end="paraboloid" if round_rate > 0 else "cone", defocus=defocus))
    if ground is not None:  # the scene's own substrate stream, so the crop is the same for a seed
        scene.substrate = _ground(ground, scene.substrate.shape, look, np.random.default_rng([int(seed) + 1, 7]))
    phi0 = float(rng.uniform(-math.pi, math.pi))  # the shaft's direction from the tip
    pivot = float(rng.uniform(100.0, 1000.0))
    extras = _Extras(seed, lobed_rate, W, look, size) if lobed_rate > 0 else None
    chips = _Flakes(seed, flake_rate, W, look) if flake_rate > 0 else None
    beads = _Beads(seed, round_rate, W, look, size) if round_rate > 0 else None
    drops = _Drops(seed, droplet_rate, W) if droplet_rate > 0 and look == "optical" else None
    edge_in = EDGE_IN if extras is None and beads is None else EDGE_IN_LOBED
    lo, hi = edge_in, size - 1 - edge_in
    tip = rng.uniform(0.3, 0.7, 2) * size
    vel = np.zeros(2)
    turn = 0.0
    blur = float(rng.uniform(0.0, max_blur))
    drift_v = rng.normal(0.0, 0.05, 2)
    shift = np.zeros(2)
    frames: list[OwnFrame] = []
    event: tuple[str, int] | None = None
    for k in range(n):
        kind = "visible"
        if event is None and events and k > 2 and rng.random() < event_rate:
            event = (["out", "occluded", "defocused"][int(rng.integers(0, 3))], int(rng.integers(1, 5)))
        sigma = blur
        particles: tuple[tuple[float, float, float], ...] = ()
        apex = tip.copy()
        phi = phi0 + turn
        if event is not None:
            kind, left = event
            if kind == "out":  # beyond the nearest edge, along the shaft's direction so the needle still shows
                d = np.array([apex[0], size - 1 - apex[0], apex[1], size - 1 - apex[1]])
                side = int(np.argmin(d))
                beyond = float(rng.uniform(10.0, 60.0))
                apex[side // 2] = -beyond if side % 2 == 0 else size - 1 + beyond
            elif kind == "occluded":
                r = float(rng.uniform(max(5.0, 0.5 * W + 3.0), max(12.0, W)))
                off = rng.normal(0.0, 0.25 * r, 2)
                off *= min(1.0, 0.6 * r / max(float(np.hypot(*off)), 1e-9))
                particles = ((float(apex[0] + off[0]), float(apex[1] + off[1]), r),)
            else:
                sigma = float(rng.uniform(7.0, 12.0))
            event = None if left <= 1 else (kind, left - 1)
        direction = np.array([math.cos(phi), math.sin(phi)])
        grains: tuple[LobedParticle, ...] = ()
        cause = ""
        if extras is not None:
            kind, cause, grains = extras.frame(k, kind, apex, tip, direction)
        flakes: tuple[Flake, ...] = ()
        if chips is not None:
            kind, cause, flakes = chips.frame(k, kind, cause, apex, direction)
        if beads is not None:
            kind, cause, grains = beads.frame(k, kind, cause, apex, tip, direction)
        lenses: tuple[Droplet, ...] = ()
        if drops is not None:
            cause, lenses = drops.frame(k, kind, cause, apex, direction)
        shift = shift + drift_v + rng.normal(0.0, 0.02, 2)
        image = scene.render(apex, direction, sigma, shift, 1.0, particles, grains, flakes, lenses)
        frames.append(OwnFrame(image, (float(apex[0]), float(apex[1])), kind, float(sigma), cause))
        # the next frame: the arm holds, glides or jumps; the needle turns about a point far up its shaft
        u = rng.random()
        if u < 0.35:
            vel = 0.8 * vel + rng.normal(0.0, 0.3, 2)
        elif u < 0.85:
            if rng.random() < 0.3:
                vel = rng.uniform(-1.0, 1.0, 2) * rng.uniform(0.0, 12.0)
        else:
            vel = np.zeros(2)
        step = vel + rng.normal(0.0, 0.3, 2)
        if rng.random() < 0.05:
            step = step + rng.uniform(-40.0, 40.0, 2)
        dturn = float(np.clip(turn + rng.normal(0.0, math.radians(0.5)), -math.radians(4.0), math.radians(4.0))) - turn
        turn += dturn
        # turning about the pivot moves the tip sideways by pivot * dturn
        side_dir = np.array([-math.sin(phi), math.cos(phi)])
        step = step - pivot * dturn * side_dir
        new = tip + step
        vel = np.where((new < lo) | (new > hi), -vel, vel)
        tip = np.clip(new, lo, hi)
        blur = float(np.clip(blur + rng.normal(0.0, 0.35), 0.0, max_blur))
    return OwnSequence(frames, W, look, ph)


class _Extras:
    """The lobed mode's events: lobed grains over the tip, the tip close to the field's edge.

    A grain (:class:`~stickslip.sim.camera.LobedParticle`) is 2 to 4 overlapping discs
    spanning 1 to 2.5 times the tip's width (at least 6 px), one lobe over the apex, the
    others grown from a lobe already placed, as dust clumps; darker than the needle (6 in
    10) or lighter, its outline softened by 0 to 1.5 px. It stays over the tip (it moves
    with it) for the 1 to 4 frames of its event. An edge event takes the tip to 4 to 12 px
    inside an edge (the one the shaft comes from, or any), gliding up to 12 px a frame,
    holds it there for 1 to 4 frames and lets it move on. Events start from frame 3.
    """

    def __init__(self, seed: int, rate: float, width_px: float, look: str, size: int) -> None:
        self.rng = np.random.default_rng([seed, 4711])
        self.rate, self.W, self.look, self.size = rate, width_px, look, size
        self.event: tuple[str, int] | None = None
        self.grain: tuple[tuple[tuple[float, float, float], ...], float, float] = ((), 0.0, 0.0)
        self.goal = (0, 0.0)

    def frame(self, k: int, kind: str, apex: NDArray[np.float64], tip: NDArray[np.float64],
              direction: NDArray[np.float64]) -> tuple[str, str, tuple[LobedParticle, ...]]:
        """Frame ``k``'s kind, cause and grains; an edge event moves ``apex`` and ``tip`` (in place)."""
        xr = self.rng
        if self.event is None and k > 2 and xr.random() < self.rate:
            self.event = (("lobed", "edge")[int(xr.integers(0, 2))], int(xr.integers(1, 5)))
            if self.event[0] == "lobed":
                self.grain = self._grain()
            else:
                axis = int(xr.integers(0, 2)) if xr.random() < 0.5 else int(np.argmax(np.abs(direction)))
                low = direction[axis] < 0 if xr.random() < 0.5 else xr.random() < 0.5
                inside = float(xr.uniform(4.0, 12.0))
                self.goal = (axis, inside if low else self.size - 1 - inside)
        if self.event is None:
            return kind, "", ()
        cause, left = self.event
        if cause == "edge":
            return self._edge(kind, apex, tip)
        self.event = None if left <= 1 else (cause, left - 1)
        if kind != "visible":
            return kind, "", ()
        discs, level, blur = self.grain
        moved = tuple((float(apex[0] + x), float(apex[1] + y), r) for x, y, r in discs)
        return "occluded", "lobed", (LobedParticle(moved, level, blur),)

    def _edge(self, kind: str, apex: NDArray[np.float64],
              tip: NDArray[np.float64]) -> tuple[str, str, tuple[LobedParticle, ...]]:
        """The tip glides (12 px a frame at most) to its goal by the edge, and stays 1 to 4 frames."""
        assert self.event is not None
        axis, goal = self.goal
        gap = goal - tip[axis]
        tip[axis] += float(np.clip(gap, -12.0, 12.0))
        if kind == "visible":
            apex[:] = tip
        if abs(gap) <= 12.0:
            cause, left = self.event
            self.event = None if left <= 1 else (cause, left - 1)
        return kind, ("edge" if abs(gap) <= 12.0 and kind == "visible" else ""), ()

    def _grain(self) -> tuple[tuple[tuple[float, float, float], ...], float, float]:
        """Lobes relative to the apex (px), the level and the outline's blur."""
        xr = self.rng
        span = max(6.0, float(xr.uniform(1.0, 2.5)) * self.W)
        r = float(xr.uniform(0.3, 0.45)) * span
        off = xr.normal(0.0, 0.25 * r, 2)
        off *= min(1.0, 0.5 * r / max(float(np.hypot(*off)), 1e-9))
        discs = [(float(off[0]), float(off[1]), r)]
        for _ in range(int(xr.integers(1, 4))):
            x0, y0, r0 = discs[int(xr.integers(0, len(discs)))]
            r = float(xr.uniform(0.25, 0.45)) * span
            a = float(xr.uniform(0.0, 2.0 * math.pi))
            d = float(xr.uniform(0.5, 0.9)) * (r0 + r)
            discs.append((x0 + d * math.cos(a), y0 + d * math.sin(a), r))
        dark = xr.random() < 0.6
        if self.look == "optical":  # what it lets through; the needle: about 0.15
            level = float(xr.uniform(0.02, 0.1) if dark else xr.uniform(0.3, 0.6))
        else:  # its yield; the needle: 0.45, brighter at its edges
            level = float(xr.uniform(0.05, 0.2) if dark else xr.uniform(0.65, 0.95))
        return tuple(discs), level, float(xr.uniform(0.0, 1.5))


class _Flakes:
    """The flake mode's events: a flat chip picked up by the tip, carried for 1 to 4 frames.

    A chip of a coating or a crystal is flat, straight-sided and nearly opaque; one the
    tip picks up swallows its end and moves and turns with it. The outline: a convex
    polygon of 3 to 6 corners spread round an ellipse (its short axis 0.35 to 1 times its
    long one: a sliver at the one end), grown by a rounding of 0.2 to 0.5 of its reach.
    Half the chips lie along the needle (within 20 degrees: dragged along), the others any
    way. It reaches 0.9 to 1.5 times the tip's width (at least 7 px) from its middle, which
    lies within 0.4 of that reach of the apex, the apex at least 0.3 tip widths inside the
    outline. Far darker than the needle in bright field; in an SEM dark or (an insulator
    charging) bright; sharper than the needle (the outline softened by at most 0.8 px).
    Events start from frame 3, on visible frames the other events left alone.
    """

    def __init__(self, seed: int, rate: float, width_px: float, look: str) -> None:
        self.rng = np.random.default_rng([seed, 2718])
        self.rate, self.W, self.look = rate, width_px, look
        self.left = 0
        self.shape: tuple[tuple[tuple[float, float], ...], float, float, float] = ((), 0.0, 0.0, 0.0)

    def frame(self, k: int, kind: str, cause: str, apex: NDArray[np.float64],
              direction: NDArray[np.float64]) -> tuple[str, str, tuple[Flake, ...]]:
        """Frame ``k``'s kind, cause and flakes (the chip's corners kept in the needle's frame)."""
        if self.left == 0 and k > 2 and kind == "visible" and not cause and self.rng.random() < self.rate:
            self.left = int(self.rng.integers(1, 5))
            self.shape = self._chip()
        if self.left == 0:
            return kind, cause, ()
        self.left -= 1
        if kind != "visible" or cause:
            return kind, cause, ()
        corners, rounding, level, blur = self.shape
        u = direction / max(float(np.hypot(*direction)), 1e-12)  # along the shaft
        v = np.array([-u[1], u[0]])
        placed = tuple((float(apex[0] + a * u[0] + b * v[0]), float(apex[1] + a * u[1] + b * v[1]))
                       for a, b in corners)
        return "occluded", "flake", (Flake(placed, rounding, level, blur),)

    def _chip(self) -> tuple[tuple[tuple[float, float], ...], float, float, float]:
        """Corners relative to the apex in the needle's frame (along, across; px), rounding, level, blur."""
        xr = self.rng
        reach = max(7.0, float(xr.uniform(0.9, 1.5)) * self.W)
        rounding = float(xr.uniform(0.2, 0.5)) * reach
        r = reach - rounding
        for _ in range(50):  # drawn again until the apex lies deep enough inside (a few draws at most)
            n = int(xr.integers(3, 7))
            angles = (np.arange(n) + xr.uniform(-0.2, 0.2, n)) * (2.0 * math.pi / n) + float(xr.uniform(0.0, math.pi))
            # a sliver dragged along by the needle lies along it (half the chips); the others any way
            along = xr.random() < 0.5
            slant = float(xr.uniform(-0.35, 0.35) if along else xr.uniform(0.0, math.pi))
            squash = float(xr.uniform(0.35, 1.0))
            c, s = math.cos(slant), math.sin(slant)
            off = xr.normal(0.0, 0.25 * reach, 2)
            off *= min(1.0, 0.4 * reach / max(float(np.hypot(*off)), 1e-9))
            pts = [(r * math.cos(t), squash * r * math.sin(t)) for t in angles]
            moved = tuple((c * x - s * y + float(off[0]), s * x + c * y + float(off[1])) for x, y in pts)
            if _depth(moved, rounding) >= 0.3 * self.W:
                break
        dark = self.look == "optical" or xr.random() < 0.5
        level = float(xr.uniform(0.0, 0.08) if dark else xr.uniform(0.8, 1.0))
        return moved, rounding, level, float(xr.uniform(0.0, 0.8))


class _Beads:
    """The round mode's events: a round opaque bead stuck on a blunt tip; the tip near the field's edge.

    A bead (a latex or silica sphere, a ball of solder or of dried dust, the objects a
    micromanipulator pushes and picks up) is round; one that sticks to the tip by its
    adhesion moves and turns with it. Its radius is 0.6 to 1.5 times the tip's width (at
    least 5 px), so its rim ahead of the tip is as blunt as the paraboloid's end; the apex
    lies inside it, 0.1 to 0.9 of its radius in from the rim, the bead's middle any way
    from the apex. Nearly opaque: in bright field it lets through 0 to 0.08 of the light
    (the needle about 0.15); in an SEM it is dark, or bright when it charges. Its outline
    is sharper than the needle's (softened by at most 0.8 px): it lies on the needle,
    closer to the objective than the needle's focus may be.
    An edge event takes the tip to 8 to 24 px inside the edge its shaft leaves the field
    by (gliding up to 12 px a frame): behind it the shaft is in the frame over a few
    stations only. It is held there for 1 to 4 frames, and each of those frames carries a
    bead (drawn at the event's start) with probability one half. Events start from
    frame 3, on visible frames the other events left alone.
    """

    def __init__(self, seed: int, rate: float, width_px: float, look: str, size: int) -> None:
        self.rng = np.random.default_rng([seed, 1618])
        self.rate, self.W, self.look, self.size = rate, width_px, look, size
        self.event: tuple[str, int] | None = None
        self.bead: tuple[tuple[float, float, float], float, float] = ((0.0, 0.0, 0.0), 0.0, 0.0)
        self.goal = (0, 0.0)

    def frame(self, k: int, kind: str, cause: str, apex: NDArray[np.float64], tip: NDArray[np.float64],
              direction: NDArray[np.float64]) -> tuple[str, str, tuple[LobedParticle, ...]]:
        """Frame ``k``'s kind, cause and bead; an edge event moves ``apex`` and ``tip`` (in place)."""
        xr = self.rng
        if self.event is None and k > 2 and kind == "visible" and not cause and xr.random() < self.rate:
            self.event = (("bead", "edge")[int(xr.integers(0, 2))], int(xr.integers(1, 5)))
            self.bead = self._bead()
            if self.event[0] == "edge":
                axis = int(np.argmax(np.abs(direction)))
                inside = float(xr.uniform(8.0, 24.0))
                self.goal = (axis, inside if direction[axis] < 0 else self.size - 1 - inside)
        if self.event is None or cause:
            return kind, cause, ()
        what, left = self.event
        with_bead = what == "bead"
        if what == "edge":
            axis, goal = self.goal
            gap = goal - tip[axis]
            tip[axis] += float(np.clip(gap, -12.0, 12.0))
            if kind == "visible":
                apex[:] = tip
            if abs(gap) > 12.0:  # still gliding there
                return kind, cause, ()
            with_bead = xr.random() < 0.5
        self.event = None if left <= 1 else (what, left - 1)
        if kind != "visible":
            return kind, cause, ()
        if not with_bead:
            return kind, "shaft-edge", ()
        (a, b, r), level, blur = self.bead
        u = direction / max(float(np.hypot(*direction)), 1e-12)  # along the shaft
        v = np.array([-u[1], u[0]])
        centre = apex + a * u + b * v
        disc = ((float(centre[0]), float(centre[1]), r),)
        return "occluded", ("bead" if what == "bead" else "bead-edge"), (LobedParticle(disc, level, blur),)

    def _bead(self) -> tuple[tuple[float, float, float], float, float]:
        """The bead's middle relative to the apex in the needle's frame (along, across; px), its radius, level
        and the outline's blur."""
        xr = self.rng
        r = max(5.0, float(xr.uniform(0.6, 1.5)) * self.W)
        depth = float(xr.uniform(0.1, 0.9)) * r
        angle = float(xr.uniform(0.0, 2.0 * math.pi))
        a, b = (r - depth) * math.cos(angle), (r - depth) * math.sin(angle)
        dark = self.look == "optical" or xr.random() < 0.5
        level = float(xr.uniform(0.0, 0.08) if dark else xr.uniform(0.8, 1.0))
        return (a, b, r), level, float(xr.uniform(0.0, 0.8))


class _Drops:
    """The droplet mode's events: a transparent droplet clinging to the tip for 1 to 4 frames.

    A tip dipped into a liquid (water, oil, a glycerol film, a condensate) comes out with a
    drop on it; the drop moves with the tip and, seen from above in bright field, is a
    plano-convex lens (:class:`~stickslip.sim.camera.Droplet`): the needle's end under it is
    seen displaced outwards from the drop's middle and magnified, the more the steeper the
    cap. An SEM's electrons are not refracted (and a liquid drop would not survive its
    vacuum): the mode makes drops in bright field only. The contact disc's radius is 0.5 to
    2 times the tip's width (at least 4 px), its middle within 0.7 of that radius of the
    apex, any way; the contact angle 40 to 90 degrees; the index 1.33 to 1.5; a third of
    the drops show no rim, a third a dark one (the steep rim's light leaving the aperture:
    0.3 to 0.7 of the light), a third a bright one (1.3 to 1.8), 1 to 2.5 px wide. The tip
    is still the tip: the frame stays ``visible`` (a fix within 3 px of it is right, a
    refusal allowed). Events start from frame 3, on visible frames the other events left
    alone.
    """

    def __init__(self, seed: int, rate: float, width_px: float) -> None:
        self.rng = np.random.default_rng([seed, 1414])
        self.rate, self.W = rate, width_px
        self.left = 0
        self.drop = ((0.0, 0.0), 0.0, 0.0, 0.0, 1.0, 0.0)

    def frame(self, k: int, kind: str, cause: str, apex: NDArray[np.float64],
              direction: NDArray[np.float64]) -> tuple[str, tuple[Droplet, ...]]:
        """Frame ``k``'s cause and droplet (its middle kept in the needle's frame)."""
        xr = self.rng
        if self.left == 0 and k > 2 and kind == "visible" and not cause and xr.random() < self.rate:
            self.left = int(xr.integers(1, 5))
            r = max(4.0, float(xr.uniform(0.5, 2.0)) * self.W)
            off = float(xr.uniform(0.0, 0.7)) * r
            angle = float(xr.uniform(0.0, 2.0 * math.pi))
            rim = (1.0, float(xr.uniform(0.3, 0.7)), float(xr.uniform(1.3, 1.8)))[int(xr.integers(0, 3))]
            self.drop = ((off * math.cos(angle), off * math.sin(angle)), r, math.radians(float(xr.uniform(40.0, 90.0))),
                         float(xr.uniform(1.33, 1.5)), rim, float(xr.uniform(1.0, 2.5)))
        if self.left == 0:
            return cause, ()
        self.left -= 1
        if kind != "visible" or cause:
            return cause, ()
        (a, b), r, angle, index, rim, rim_width = self.drop
        u = direction / max(float(np.hypot(*direction)), 1e-12)  # along the shaft
        v = np.array([-u[1], u[0]])
        centre = apex + a * u + b * v
        return "droplet", (Droplet((float(centre[0]), float(centre[1])), r, angle, index, rim, rim_width),)


def _depth(corners: tuple[tuple[float, float], ...], rounding: float) -> float:
    """How far the origin lies inside a convex polygon grown by ``rounding`` (px; negative: outside)."""
    pts = np.asarray(corners, dtype=float)
    best, inside = math.inf, True
    area = float(np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1]))
    for a, b in zip(pts, np.roll(pts, -1, axis=0), strict=True):
        e = b - a
        t = float(np.clip(-a @ e / max(float(e @ e), 1e-12), 0.0, 1.0))
        best = min(best, float(np.hypot(*(a + t * e))))
        inside &= math.copysign(1.0, area) * float(e[0] * -a[1] - e[1] * -a[0]) >= 0.0
    return rounding + (best if inside else -best)


def own_benchmark(n_frames: int = 400, per_sequence: int = 40, seed: int = 0, size: int = 256,
                  widths: tuple[float, float] = (3.0, 20.0), looks: tuple[str, ...] = ("optical", "sem"),
                  lobed_rate: float = 0.0, flake_rate: float = 0.0, round_rate: float = 0.0,
                  droplet_rate: float = 0.0, defocus: str = "gaussian") -> list[OwnSequence]:
    """Sequences of ``per_sequence`` frames, tip widths spread over ``widths`` (px), the looks taken in turn;
    ``lobed_rate``, ``flake_rate``, ``round_rate``, ``droplet_rate``: :func:`own_sequence`'s modes (0: the plain
    frames); ``defocus``: its blur's shape."""
    n_seq = max(1, n_frames // per_sequence)
    ws = np.linspace(widths[0], widths[1], n_seq)
    return [own_sequence(seed * 1000 + i, per_sequence, size, float(ws[i]), looks[i % len(looks)],
                         lobed_rate=lobed_rate, flake_rate=flake_rate, round_rate=round_rate,
                         droplet_rate=droplet_rate, defocus=defocus) for i in range(n_seq)]


def lobed_benchmark(n_frames: int = 200, per_sequence: int = 40, seed: int = 0, size: int = 256,
                    lobed_rate: float = 0.15, widths: tuple[float, float] = (3.0, 20.0),
                    looks: tuple[str, ...] = ("optical", "sem"), defocus: str = "gaussian") -> list[OwnSequence]:
    """:func:`own_benchmark`'s sequences in the lobed mode (lobed grains, tips near the edge)."""
    return own_benchmark(n_frames, per_sequence, seed, size, widths, looks, lobed_rate=lobed_rate, defocus=defocus)


def flake_benchmark(n_frames: int = 200, per_sequence: int = 40, seed: int = 0, size: int = 256,
                    flake_rate: float = 0.15, widths: tuple[float, float] = (3.0, 20.0),
                    looks: tuple[str, ...] = ("optical", "sem"), defocus: str = "gaussian") -> list[OwnSequence]:
    """:func:`own_benchmark`'s sequences in the flake mode (flat chips stuck on the tip)."""
    return own_benchmark(n_frames, per_sequence, seed, size, widths, looks, flake_rate=flake_rate, defocus=defocus)


def round_benchmark(n_frames: int = 200, per_sequence: int = 40, seed: int = 0, size: int = 256,
                    round_rate: float = 0.15, widths: tuple[float, float] = (3.0, 20.0),
                    looks: tuple[str, ...] = ("optical", "sem"), defocus: str = "gaussian") -> list[OwnSequence]:
    """:func:`own_benchmark`'s sequences in the round mode (blunt needles, beads stuck on the tip, tips near the
    edge their shaft leaves by)."""
    return own_benchmark(n_frames, per_sequence, seed, size, widths, looks, round_rate=round_rate, defocus=defocus)


def droplet_benchmark(n_frames: int = 200, per_sequence: int = 40, seed: int = 0, size: int = 256,
                      droplet_rate: float = 0.15, widths: tuple[float, float] = (3.0, 20.0),
                      looks: tuple[str, ...] = ("optical",), defocus: str = "gaussian") -> list[OwnSequence]:
    """:func:`own_benchmark`'s sequences in the droplet mode (transparent droplets on the tip; bright field only)."""
    return own_benchmark(n_frames, per_sequence, seed, size, widths, looks, droplet_rate=droplet_rate, defocus=defocus)


MICROGRAPHS = {"micro": "microaneurysms.png", "retina": "retina.jpg"}
"""The micrograph mode's grounds: scikit-image's shipped files the second renderer does not use (it takes
``cell.png`` and ``ihc.png``): ``microaneurysms.png`` zoomed 4 times (cubic), and the middle 800 x 800 px of
``retina.jpg``'s green channel (its vessels: needle-scale dark lines)."""

GROUND_CONTRAST = 0.145
"""The micrograph ground's contrast in bright field (SEM: 0.35 of it): 0.145 times the ground scaled to a spread
of 0.5, about 8.5 % of the 0.85 mean brightness."""


@functools.cache
def micrograph(name: str) -> NDArray[np.float64] | None:
    """The micrograph ``name`` (a key of :data:`MICROGRAPHS`) as a grey float image in [0, 1]; ``None``
    without scikit-image (the dev extra: it ships the files)."""
    spec = importlib.util.find_spec("skimage")
    if spec is None or not spec.submodule_search_locations:
        return None
    from PIL import Image
    from scipy import ndimage

    path = Path(list(spec.submodule_search_locations)[0]) / "data" / MICROGRAPHS[name]
    if not path.exists():
        return None
    with Image.open(path) as im:
        if name == "retina":
            return np.asarray(im, dtype=float)[300:1100, 300:1100, 1] / 255.0
        return np.asarray(ndimage.zoom(np.asarray(im.convert("L"), dtype=float) / 255.0, 4, order=3), dtype=float)


def _ground(src: NDArray[np.float64], shape: tuple[int, ...], look: str,
            rng: np.random.Generator) -> NDArray[np.float64]:
    """A ``shape`` crop of ``src`` (mirrored past its edges) at a corner drawn from ``rng``, as a substrate:
    zero mean over the crop, :data:`GROUND_CONTRAST` times the micrograph scaled to a spread of 0.5."""
    h, w = shape
    big = np.pad(src, ((0, h), (0, w)), mode="symmetric")
    y0, x0 = int(rng.integers(0, src.shape[0])), int(rng.integers(0, src.shape[1]))
    img = (big[y0 : y0 + h, x0 : x0 + w] - float(np.mean(src))) / (np.std(src) * 2.0 + 1e-9)
    img = img - img.mean()
    if look == "optical":
        return np.asarray(0.85 + GROUND_CONTRAST * img, dtype=float)
    return np.asarray(0.25 + GROUND_CONTRAST * 0.35 * img, dtype=float)


def micrograph_benchmark(ground: str, seed: int, n_seq: int = 40, per_sequence: int = 40,
                         size: int = 256, defocus: str = "gaussian") -> list[OwnSequence]:
    """The micrograph mode: ``n_seq`` bright-field sequences over the micrograph ``ground`` (:data:`MICROGRAPHS`),
    tips 10 to 18 px, 50 to 120 photons (drawn per sequence), events at 0.15 a frame; empty without
    scikit-image."""
    if micrograph(ground) is None:
        return []
    return [micrograph_sequence(ground, seed, s, per_sequence, size, defocus) for s in range(n_seq)]


def micrograph_sequence(ground: str, seed: int, index: int, per_sequence: int = 40, size: int = 256,
                        defocus: str = "gaussian") -> OwnSequence:
    """Sequence ``index`` of :func:`micrograph_benchmark`'s set (``ground``, ``seed``); scikit-image needed."""
    src = micrograph(ground)
    if src is None:
        raise RuntimeError("the micrograph mode needs scikit-image (the dev extra: it ships the files)")
    rng = np.random.default_rng([seed, index, 99])
    width, photons = float(rng.uniform(10.0, 18.0)), float(rng.uniform(50.0, 120.0))
    return own_sequence(seed * 1000 + index, per_sequence, size, width_px=width, look="optical", photons=photons,
                        event_rate=0.15, ground=src, defocus=defocus)
