"""What the tracker learns of the tip from the first frame: a template, its weights, a blur bank.

From one frame and the tip's pixel the tracker cuts a square window centred on the tip
and weighs each of its pixels by how much it belongs to the needle (docs/vision.md,
"Decision rules"):

* the window's **background level** is the median of its outer ring, its **spread** the
  ring's median absolute deviation (texture and noise together);
* a pixel of the smoothed window that stands more than :attr:`TrackerParams.contrast`
  spreads from the background is needle; the needle is the connected region touching the
  tip (within a few pixels), grown by :attr:`TrackerParams.edge_px` so its edges count;
* weights fall off with the distance from the tip (Gaussian of ``window / 2``): the shaft
  far behind the tip says least about where the tip is and most about a turn.

The template is kept with extra blur (a bank of Gaussian blurs, :attr:`TrackerParams.blur_bank`):
a tip that drifts out of focus is matched against the template blurred alike.
:func:`masked_ncc` is the weighted normalised cross-correlation of the template over a
region of a frame, by FFT; :func:`inside_ncc` the same where the template may hang over the
frame's border, the part outside left out of the sums.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import fft, ndimage

__all__ = ["TrackerParams", "TipTemplate", "TemplateError", "masked_ncc", "inside_ncc", "region_spectra",
           "noise_sigma"]

FloatArray = NDArray[np.float64]


class TemplateError(ValueError):
    """Nothing that can be tracked stands at the tip given (the message says why)."""


@dataclass(frozen=True)
class TrackerParams:
    """The tip tracker's constants, each with its unit and reason (docs/vision.md).

    Attributes
    ----------
    half_window : int
        Half the side of the template window, px: the tip and ~20 px of its shaft.
    contrast : float
        A pixel is needle when it stands this many background spreads from the
        background level (smoothed over 1 px), 1.
    edge_px : int
        Needle mask grown by this many pixels, px: the edges carry the position.
    blur_bank : tuple of float
        Extra Gaussian blur of the template's copies, px (sigma): matched against a tip
        out of focus.
    sharpen_bank : tuple of float
        Extra Gaussian blur of the *frame*, px (sigma), matched against the sharp
        template: a tip in better focus than in the first frame.
    search_radius : int
        How far from the last fix the tip is looked for before the whole frame is, px.
    coarse_factor : int
        Down-sampling of the whole-frame search, 1 (the down-sampled frame is padded so the
        template may hang over its border until the tip lies on the edge).
    candidates : int
        Peaks of the whole-frame search refined before giving up, 1.
    min_score : float
        Least weighted correlation of a fix with the template, 1 (below: lost).
    reacquire_score : float
        Least correlation to take a tip found again by the whole-frame search, 1.
    max_sigma : float
        Largest standard deviation of a fix, px (above: the tip's position is not
        determined, e.g. only the shaft is seen); a fix 3 px off is then a 3-sigma event.
    edge_margin : float
        A fix nearer the field's edge than this plus twice its blur is refused as out of
        the field, px: a tip just beyond the edge looks like one on it.
    min_coverage : float
        Least share of the template's weight that must lie in the frame, 1 (below: out of
        the field); the whole-frame search does not look where less lies in it.
    occluded_fraction : float
        Largest share of the template's weight that may disagree with the frame, 1
        (above: something covers the tip).
    max_blur : float
        Largest extra blur of a fix, px (sigma); a tip further out of focus is refused.
    sigma_floor : float
        Smallest standard deviation reported for a fix, px.
    sigma_factor : float
        Multiplies the fit's standard deviation, 1: the fit counts every pixel as an
        independent measurement, but after smoothing by ``template_blur`` (sigma ``s``)
        about ``4 pi s²`` neighbouring pixels share their noise, so the fit alone is
        optimistic by ``2 sqrt(pi) s`` (3.5 at 1 px).
    template_blur : float
        The first frame's window, and every frame where it is fitted, are smoothed by
        this Gaussian (sigma, px): the template's own noise would otherwise favour the
        blurred copies, and what the camera under-samples (aliasing at a sharp edge)
        would pull the fit towards the pixel grid.
    level_hysteresis : float
        Another blur copy replaces the current one only when it correlates better by
        this much, 1.
    mismatch_ratio, mismatch_floor : float
        A fix's mismatch ``1 - score`` may be at most ``mismatch_ratio`` times the
        median mismatch of the last :attr:`recent` fixes plus ``mismatch_floor``, 1:
        the noise, blur and background of a sequence set what a good match scores, and
        a tip under a particle, or something else taken for it, scores worse. The floor
        is what a clean sequence's good fixes may stray beyond the ratio (the own sets'
        good fixes: at most 0.014); at 0.03 a tip seen through a droplet (own) and one
        under an opaque particle were fixed 3.2 to 3.5 px off at 14 to 19 times the
        recent mismatch, 0.022 to 0.026 beyond the ratio.
    first_mismatch_slack : float
        Before three fixes a fix's mismatch may be at most ``mismatch_ratio`` times the
        first frame's (what its noise alone costs a perfect match) plus this, 1: the first
        frame's noise does not say what motion, focus and background will cost (good
        early fixes of the own sets stray up to 0.060 beyond the ratio, the third
        generator's to 0.072; its one early fix 3.1 px off strays 0.050; docs/vision-log.md).
    recent : int
        Fixes that set the expected mismatch, 1.
    max_turn : float
        Largest turn of the needle against the first frame, rad: a fit that needs more
        has matched something else (a microscope's needle turns by a few degrees).
    reacquire_ratio, reacquire_sigma : float
        A tip found again by the whole-frame search must match as well as the recent
        fixes (its mismatch at most ``reacquire_ratio`` times their median, plus the
        floor), with a standard deviation of at most ``reacquire_sigma`` px and no more
        than one blur copy beyond the last fix's: a search over the whole frame meets
        many things that resemble a blurred tip a little, and a false fix there would
        be far off.
    unvouched_sigma : float
        Largest standard deviation of a tip found again (or of a fit near the last fix that
        passes the rules for one) where fewer than :attr:`width_stations` of the needle's
        width stations lie in the frame behind it (nothing else vouches for it), px: on the
        own renderer's sets the wrong candidates of this kind read 0.61-0.97 px and
        ``reacquire_sigma`` alone would leave a margin of 0.01 px; 0.5 keeps one of 0.1 px
        (docs/vision-log.md, twelfth round; the fits near the last fix, the nearest wrong one
        0.61 px: "The vetoes taken together").
    max_blur_step : float
        Largest change of the tip's blur between two consecutive fixes, px (sigma): focus
        drifts slowly, and a match that needs a very different blur copy is something
        else (a blob that looks like the tip blurred, or the tip's edge under a particle).
        The last fix's blur is the copy that matches best on its own pixels when the one it
        was fitted with is beyond the step (that one lags a drifting focus; docs/vision.md).
    reacquire_ncc : float
        A peak of the whole-frame search is fitted only when the template correlates with
        the frame there by this much at whole pixels, 1: the fit costs as much as the
        search, and a tip found again must correlate by ``reacquire_score`` anyway.
    edge_near : float
        The needle's edges right behind a fix (within 4.5 px) must keep at least this share
        of their contrast further back (:mod:`.edges`), 1: a particle over the tip, or a fix
        ahead of the tip, interrupts them there.
    edge_contrast : float
        The needle's edges behind a fix (6 to 14 px back) must have at least this share of
        the template's contrast there, 1: a fit on plain ground (whose shading the
        brightness planes explain) finds them faint or missing.
    edge_shape : float
        The profiles across the shaft behind a fix must correlate with the template's
        by at least this much (the median over the stations, each shifted by up to 1 px
        and its level and slope taken out), 1: the needle's two edges are where the
        template has them, not a blob's or the ground's.
    along_limit : float
        Largest displacement of a fix along the needle's axis that the shaft's taper may
        show (:mod:`.shaft`), px, plus ``along_sigmas`` standard deviations of that
        estimate: issue 30's limit for a fix (a fix more than 3 px from the tip is a
        defect), so a grain as dark as the needle prolonging it is not taken for its end.
    along_sigmas : float
        Standard deviations of the taper's estimate (from the pixel noise at the stations)
        allowed beyond ``along_limit``, 1: a fix is refused only where the taper is sure.
        The two also set what the needle's width may differ by at each station behind a
        fix (:mod:`.width`): what ``along_limit`` px along the axis change it through the
        first frame's taper, plus ``along_sigmas`` standard deviations of the width
        measured; a fix is refused (occluded) where the stations' median difference is
        beyond that: behind the far end of something stuck on the tip the dark is wider
        (the thing) or narrower (the needle's own tip further back) than the needle.
    width_shift : float
        Largest outward shift of each edge tried when measuring a station's width, px: a
        station beyond it disagrees anyway, and a wider search would reach past the
        ground the first frame showed plain beside the needle.
    width_slack : float
        A station whose width in the first frame lies further than this from the needle's
        straight taper (a robust line through all the stations' widths) is not used for
        the width, px (the needle's run across the shaft is measured in whole pixels on
        either side): a needle widens steadily away from its tip, so something lay beside
        it there, or the run found was not the needle's.
    extent_depth : float
        A width station's extent is compared (``extent_slack``) only where the first frame's
        needle stands this many times ``contrast`` background spreads from the ground (the
        median over the station's extent), 1: its edges are then crossed by the threshold
        well above their foot, where blur and noise hardly move them; an SEM needle's edge
        contrast (1 to 1.5 times) is not measured so.
    extent_slack : float
        How much narrower than the first frame's, beyond what ``along_limit`` px along the
        axis change it through the taper, the needle's extent across the shaft (the first to
        the last sample standing ``contrast`` spreads from the ground) may be at any width
        station behind a fix, px: whole samples on either edge and their jitter (up to 3.5
        px behind the own frames' good fixes). Behind an occluder's far end taken for the
        tip the needle, past the occluder, is its own further back: narrower, or to the side.
    width_narrow : float
        How much narrower than what each width station allows (``along_limit`` px of the taper plus
        ``along_sigmas`` standard deviations) the registered width ``dw`` may be at any one station behind a
        fix, px (``inf``: no such rule, the stations' median alone): anything beside the needle only widens
        it, so one station suffices, as for the extent; but on a structured ground (a real micrograph) the
        extent's threshold takes the ground for needle and reads wider, where the registration still reads
        the needle's own edges. The registration's error beyond its matched-filter deviation (the ground's
        structure is not pixel noise): up to 2.3 px behind the own sets' good fixes, 1.4 px over own
        micrograph grounds (docs/vision-log.md, "An occluded tip on a real micrograph").
    focus_top_read : bool
        Whether a fit with the copy next to the most blurred is refused as out of focus when the most blurred
        copy matches it at least as well there (``True``), or only when the fit chose the most blurred copy
        (``False``). The copy a fit settles on keeps the one it was found with unless another matches better by
        ``level_hysteresis``, a choice meant to keep the copy steady between near-equal neighbours; and a tip
        blurred past the bank, fitted with too little blur, sits behind the tip, where the two top copies
        match about equally (docs/vision-log.md, "The own renderer over real micrographs").
    width_near_wide : float
        How much wider than they allow (``width_narrow``'s allowance) the two width stations nearest a fix may
        both be, px (``inf``, the default: no such rule): an occluder over the tip about as wide as the needle
        widens the stations it covers, the nearest ones, and on a long shaft the stations further back outvote
        them in the median. 1 px refuses the own micrograph mode's one such fix (1.8 px) and no good own fix
        (at most 0.2 px), but one good fix (1.2 px off) of the second renderer's and no wrong one: off
        (docs/vision-log.md, "The own renderer over real micrographs").
    width_stations : int
        Least number of the width's stations (:mod:`.width`) that must lie in the frame
        behind a fix for the width to be checked, 1: the check is a median over them.
    trust_unchecked : bool
        Whether a fix behind which fewer than ``width_stations`` lie in the frame (where the
        first frame showed three or more) is taken unchecked (``True``: the other rules
        decide) or refused (``False``: lost): a round opaque particle over a blunt end mimics
        the end's outline (its chord is as wide as the needle over about its radius), and
        only the shaft's width further back tells them apart, so a fix nothing vouches for
        is not given.
    vouch_unlearnt : bool
        Whether a fix is to be vouched for (as one behind which too few stations lie in the frame: the
        found-again rules or the outline) also where the first frame itself showed fewer than
        ``width_stations`` width stations (``True``), or is taken unchecked there (``False``, the
        default): a needle whose shaft the ground's structure cuts short in the first frame (a real
        micrograph's dark band across it) is otherwise vouched for by nothing behind its tip, and an
        occluder's far rim is taken for the tip; but on the own sets it refuses 22 good fixes (0.05 to
        2.7 px off) for that one wrong fix, most of a sequence whose first frame learns no station
        (docs/vision-log.md, "An occluded tip on a real micrograph").
    outline_reach : float
        How far behind a fit nothing else vouches for (fewer than ``width_stations`` in the frame) its
        outline must be read on at least one edge for the outline to vouch for it, px (``inf``: never): a
        bead over the tip taken for it shows its outline closing 8 to 22 px behind the fit on the own round
        mode; read to 10 px, a bead 7 px off was vouched for, from 12 px none (docs/vision-log.md,
        "Vouching near the edge from one edge of the outline").
    outline_slack : float
        How far each edge of that outline may move inward going back, and lie from the first frame's
        (its median shift), px: behind a fix that is the tip an edge lies where the first frame had it
        (159 of the own sets' 163 good fits of this kind close by less), behind a bead's rim taken for
        the tip the outline closes (2.6 px or more) or stands out along the shaft (2.8 px or more).
    weight_falloff : float
        The Gaussian sigma of the weights' fall-off with the distance from the tip, as a share
        of ``half_window``, 1 (``inf``: none): the shaft far behind the tip says little about
        where the tip is, and much about a turn (0.7 and 1.0 refuse fewer own plain tips but
        raise the medians and give fixes > 3 px off; docs/vision-log.md, "The fit's efficiency").
    lap_blur : float
        The template is smoothed by this Gaussian (sigma, px) more before its Laplacian, the
        blur term's column: of the template itself the Laplacian would be mostly its noise
        (1.5 and 2 take part of the template noise's bias away, but refuse more own plain
        tips and give fixes > 3 px off; the same section).
    thin_blur : float
        A blur copy as blurred as this or more (its blur and the smoothing every frame
        gets, Gaussian sigma, px) is fitted on every second pixel, a chequerboard.
    average_frames : int
        The template is made again, once, from the first frame's window and the next this many
        fixes' fitted with the sharp copy (:mod:`.average`), 1: the first frame's noise alone
        biases the blur term and a round end's fix ahead of the tip. 0 (the default) keeps the
        first frame's: with 8, the own sets' median and 95th percentile fell on six of seven,
        but the second renderer's 95th percentile rose (1.157 to 1.197 px; docs/vision-log.md).
    anchor_limit : float
        Largest move of the averaged template's apex that its fit to the first frame may ask,
        px (the own renderer's: 0.02 to 0.3 px); beyond, the first frame's template is kept.
    front_fraction : float
        Largest share of the half-ring in front of the tip that may look like the needle,
        1: where the needle seems to end at something as dark (or bright) as itself, the
        end seen is that thing's edge, not the tip (occluded).
    confirm_move : float
        Once a fix lies this far from the first frame's tip, px, each region of the template's
        mask is compared with that frame where the first frame had it and where the fix puts it
        (:mod:`.confirm`): one that stayed with the ground is dropped and the fix fitted again.
        Twice the mask's growth (``edge_px``) and the 1 px smoothing: a region moved by less
        overlaps its old place and the two readings do not differ. ``inf`` turns it off.
    confirm_margin : float
        A region is ground when it correlates at its old place better than at the fix's by this
        much, 1: a piece of the shaft moving along the needle's axis looks alike at both places,
        and a tie is kept (it matches where the needle is anyway). Own cases: bright cells learnt
        beside a needle read 0.16 to 0.18 better at their old place, the own sets' needle pieces
        0.26 or more worse (docs/vision-log.md).
    focus_from : float
        Where the shaft whose two edges say how blurred the first frame is starts behind the tip,
        px (:func:`~.focus.first_frame_focus`): past the apex's cap of the own needles up to 20 px
        wide. Read for ``camera locate``'s warning only; the tracker never uses it.
    focus_length : float
        Length of that shaft, px: 40 px of two edges read own bright-field first frames' blur
        unbiased (Gaussian defocus, within 0.08 px) with a spread of 0.05-0.17 px (track73).
    focus_warn : float
        The first frame's blur read there (the edges' sigma, px) over which ``camera locate``
        warns that it looks out of focus: on own bright-field sequences the fixes' median error
        doubles past a first frame blurred 1.6 px (0.26 px under 0.8 px, 0.52 px over 1.6 px),
        and at 1.6 px the reading warned on none of 66 sharp first frames (< 0.8 px) and
        missed none of 142 blurred ones (> 1.6 px) (track73). SEM edges read about 0.5 px low.
    shaft_start_deg : float
        A tip given on the needle's shaft is refused when the needle found there reaches the window's outer
        ring (its outer 4 px, where the background is read) in two directions within this angle of opposite,
        deg: a patch of two parallel edges looks the same moved along its axis (a tip moving 4 px a frame was
        tracked as 0.4 px, scores ~1.0; audit40). A needle's end reaches the ring on one side only.
    needle : bool
        Place each fix by a parametric needle fitted to the frame, its blur free (:mod:`.needle`; track79, off:
        an experiment): the template's fit is its start, the needle's end (at the first frame's offset from the
        tip) its position, its covariance the fix's sigma.
    needle_half : int
        The needle's fit reads the pixels within this distance of its start, px (the template's window: the
        tip and ~20 px of its shaft).
    needle_move : float
        Largest distance between the needle's tip and the template's fix, px (beyond: the template's fix is
        kept; a needle fitted to something else), and between the first frame's tip and the model's end there.
    needle_sigma : bool
        With ``needle``, the fix's covariance is the needle's fit's (off: the template's; on, the sigma rule
        refused 370 more visible tips of the own 13 sets, track79).
    needle_along : bool
        With ``needle``, the fix moves only along the needle's axis to the needle's tip (the blur's error lies
        along it), its place across kept as the template's fit put it.
    needle_judge : bool
        With ``needle``, the decision rules read the template's fit (its place, sigma and copy, as without the
        stage) and a fix they take is then placed at the needle's tip; off, they read the needle's place (and
        took 6 more occluded tips of the own 13 sets, placed 2-3 px ahead of the grain's far side, track79).
    needle_state : bool
        With ``needle`` and ``needle_judge``, the tracker keeps the needle's tip as its last fix, where the next
        frame's search starts (on: 3 more visible tips of the own 13 sets refused, one sequence's 44 px jump
        at the search's reach, track79); off, it keeps the template's fit and every decision is as without the
        stage: only the fixes' places change.
    """

    half_window: int = 20
    contrast: float = 3.0
    edge_px: int = 2
    blur_bank: tuple[float, ...] = (0.0, 1.0, 2.0, 3.0, 4.5, 6.0)
    sharpen_bank: tuple[float, ...] = (1.5, 3.0)
    search_radius: int = 32
    coarse_factor: int = 4
    candidates: int = 3
    min_score: float = 0.6
    reacquire_score: float = 0.8
    max_sigma: float = 1.0
    edge_margin: float = 3.0
    min_coverage: float = 0.5
    occluded_fraction: float = 0.3
    max_blur: float = 5.0
    sigma_floor: float = 0.03
    sigma_factor: float = 3.5
    template_blur: float = 1.0
    mismatch_ratio: float = 4.0
    mismatch_floor: float = 0.02
    first_mismatch_slack: float = 0.1
    recent: int = 10
    max_turn: float = 0.2
    front_fraction: float = 0.3
    reacquire_ratio: float = 1.5
    reacquire_sigma: float = 0.6
    unvouched_sigma: float = 0.5
    reacquire_ncc: float = 0.5
    level_hysteresis: float = 0.01
    max_blur_step: float = 2.0
    edge_near: float = 0.6
    edge_contrast: float = 0.6
    edge_shape: float = 0.9
    along_limit: float = 3.0
    along_sigmas: float = 3.0
    width_stations: int = 3
    trust_unchecked: bool = False
    outline_reach: float = 16.0
    outline_slack: float = 2.0
    width_shift: float = 5.0
    width_slack: float = 2.0
    extent_depth: float = 2.0
    extent_slack: float = 5.0
    width_narrow: float = 3.0
    vouch_unlearnt: bool = False
    focus_top_read: bool = True
    width_near_wide: float = math.inf
    weight_falloff: float = 0.5
    lap_blur: float = 1.0
    thin_blur: float = 2.2
    average_frames: int = 0
    anchor_limit: float = 1.0
    confirm_move: float = 4.0
    confirm_margin: float = 0.1
    focus_from: float = 10.0
    focus_length: float = 40.0
    focus_warn: float = 1.6
    shaft_start_deg: float = 22.5
    needle: bool = False
    needle_half: int = 20
    needle_move: float = 4.0
    needle_sigma: bool = False
    needle_along: bool = True
    needle_judge: bool = True
    needle_state: bool = False

    def __post_init__(self) -> None:
        if not 6 <= self.half_window <= 128:
            raise ValueError(f"half_window = {self.half_window} px must be in 6..128")
        if self.search_radius < 4 or self.coarse_factor < 1 or self.candidates < 1:
            raise ValueError("search_radius >= 4 px, coarse_factor >= 1 and candidates >= 1")
        if not (0 < self.min_score <= self.reacquire_score <= 1):
            raise ValueError("0 < min_score <= reacquire_score <= 1")
        if not self.blur_bank or self.blur_bank[0] != 0.0 or list(self.blur_bank) != sorted(self.blur_bank):
            raise ValueError("blur_bank must start at 0 px and increase")
        if not (self.width_shift >= 1 and self.width_slack >= 0 and self.width_stations >= 1):
            raise ValueError("width_shift >= 1 px, width_slack >= 0 px and width_stations >= 1")
        if not (self.extent_depth > 0 and self.extent_slack >= 0):
            raise ValueError("extent_depth > 0 and extent_slack >= 0 px")
        if not (self.average_frames >= 0 and self.anchor_limit > 0):
            raise ValueError("average_frames >= 0 and anchor_limit > 0 px")
        if not (self.weight_falloff > 0 and self.lap_blur > 0):
            raise ValueError("weight_falloff > 0 (a share of half_window; inf: none) and lap_blur > 0 px")
        if not 0.0 < self.shaft_start_deg < 90.0:
            raise ValueError(f"shaft_start_deg = {self.shaft_start_deg} deg must be in (0, 90)")
        if self.edge_px < 0:
            raise ValueError(f"edge_px = {self.edge_px} px must be >= 0 (the mask is grown, never shrunk)")


def noise_sigma(image: FloatArray) -> float:
    """Standard deviation of a frame's pixel noise (robust: the MAD of a pixel against its neighbours).

    At least the rounding noise of a 16-bit camera over the frame's range (its span / 65535 / √12):
    a rendered, noise-free frame has a MAD of 0, and every weight the tracker makes from the noise
    would divide by it.
    """
    d = image[1:-1, 1:-1] - 0.25 * (image[:-2, 1:-1] + image[2:, 1:-1] + image[1:-1, :-2] + image[1:-1, 2:])
    mad = float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(1.25))
    span = float(np.max(image) - np.min(image)) if image.size else 0.0
    return max(mad, span / 65535.0 / math.sqrt(12.0))


def _window(image: FloatArray, cx: int, cy: int, h: int) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The ``(2h+1)²`` window centred on pixel ``(cx, cy)`` and which of its pixels lie in the frame."""
    H, W = image.shape
    n = 2 * h + 1
    out = np.zeros((n, n))
    inside = np.zeros((n, n), dtype=bool)
    y0, x0 = cy - h, cx - h
    ys, xs = max(0, y0), max(0, x0)
    ye, xe = min(H, y0 + n), min(W, x0 + n)
    if ye > ys and xe > xs:
        out[ys - y0 : ye - y0, xs - x0 : xe - x0] = image[ys:ye, xs:xe]
        inside[ys - y0 : ye - y0, xs - x0 : xe - x0] = True
    return out, inside


@dataclass
class TipTemplate:
    """The tip as learned from one frame (see the module docstring).

    Attributes
    ----------
    bank : list of ndarray
        The template window, then its copies with the extra blurs of ``params.blur_bank``.
    weights : ndarray
        Weight of each window pixel (0..1): needle, its edges, near the tip.
    level_weights : list of ndarray
        The weights of each blur copy, then of each frame blur (``sharpen_bank``): the
        mask grown by twice the extra blur more.
    shaft : tuple of float
        Unit vector from the tip back along the needle, window axes.
    core, ring, front : tuple of ndarray
        Offsets from the tip (x, y; px) of the needle's core near the tip, of the
        background around it (away from the needle), and of the background in front of
        the tip (within 60 deg of straight ahead, 2 to 14 px away, clear of the needle).
    mask : ndarray of bool
        The needle's pixels in the window (those standing out from the background,
        connected to the tip).
    ground : tuple of float
        The background's level and spread (grey units) the needle was told from: the
        median of the window's outer ring, smoothed by 1 px, and its scaled median
        absolute deviation.
    apex : tuple of float
        The tip in window coordinates, px ``(x, y)``.
    noise : float
        Pixel noise of the first frame (grey units).
    contrast : float
        Weighted standard deviation of the template over its weights (grey units): what
        the needle stands out by.
    """

    bank: list[FloatArray]
    weights: FloatArray
    apex: tuple[float, float]
    noise: float
    contrast: float
    params: TrackerParams = field(default_factory=TrackerParams)
    level_weights: list[FloatArray] = field(default_factory=list)
    shaft: tuple[float, float] = (1.0, 0.0)
    core: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
    ring: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
    front: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
    mask: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    ground: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def learn(cls, image: FloatArray, tip: tuple[float, float], params: TrackerParams = TrackerParams()) -> TipTemplate:
        """The template of the tip at pixel ``tip`` (x, y) of ``image``.

        Raises :class:`TemplateError` if nothing trackable stands there.
        """
        x, y = float(tip[0]), float(tip[1])
        _check_tip(image.shape, x, y)
        h = params.half_window
        cx, cy = int(round(x)), int(round(y))
        win, inside = _window(image, cx, cy, h)
        if not inside.all():  # near the edge: fill with the ring's level, weight 0
            fill = float(np.median(win[inside]))
            win = np.where(inside, win, fill)
        apex = (x - cx + h, y - cy + h)
        noise = noise_sigma(image)
        mask, ground = _needle_mask(win, inside, apex, noise, params, (x, y))
        through = _passes_through(mask, apex, h, params.shaft_start_deg)
        if through is not None:
            raise TemplateError(f"the pixel ({x:g}, {y:g}) is on the needle's shaft, not at its end: {through}")
        level_weights = _level_weights(mask, inside, apex, params)
        weights = level_weights[0]
        shaft, core, ring_off, front = _surroundings(mask, inside, apex, params)
        s0 = params.template_blur
        bank = [ndimage.gaussian_filter(win, math.hypot(s0, b), mode="nearest") for b in params.blur_bank]
        # the frames are smoothed by s0 alike before the fit (sampling.patch): copy k then matches a frame
        # blurred by blur_bank[k] more than the first
        contrast = _trackable_contrast(win, weights, noise, (x, y))
        return cls(bank, weights, apex, noise, contrast, params, level_weights, shaft, core, ring_off, front, mask,
                   ground)

    @property
    def half(self) -> int:
        return self.params.half_window


Offsets = tuple[FloatArray, FloatArray]


def _check_tip(shape: tuple[int, ...], x: float, y: float) -> None:
    """:class:`TemplateError` unless the tip (x, y; px) is a finite pixel at least 4 px inside the frame."""
    H, W = shape
    if not (math.isfinite(x) and math.isfinite(y)):
        raise TemplateError(f"the tip ({x}, {y}) is not a finite pixel")
    if not (-0.5 <= x < W - 0.5 and -0.5 <= y < H - 0.5):
        raise TemplateError(f"the tip ({x:g}, {y:g}) is outside the {W} x {H} frame (x right, y down, from 0)")
    margin = 4
    if min(x, y, W - 1 - x, H - 1 - y) < margin:
        raise TemplateError(
            f"the tip ({x:g}, {y:g}) is within {margin} px of the frame's edge: too close to learn it"
        )


_WHAT_TO_DO = "put the tip on the needle's very end, or start with a frame in focus where the needle stands out more"


def _offsets(h: int, apex: tuple[float, float]) -> Offsets:
    """Each pixel's offset from the tip ``apex`` (x, y; px) in the window of half-width ``h`` (px)."""
    yy, xx = np.mgrid[0 : 2 * h + 1, 0 : 2 * h + 1]
    return xx - apex[0], yy - apex[1]


def _needle_mask(
    win: FloatArray, inside: NDArray[np.bool_], apex: tuple[float, float], noise: float, params: TrackerParams,
    tip: tuple[float, float],
) -> tuple[NDArray[np.bool_], tuple[float, float]]:
    """The pixels of the needle at the tip: those standing out from the window's ring, connected to the tip, and
    the ring's level and spread (grey units).

    Raises :class:`TemplateError` when the ring lies outside the frame, when nothing stands out within 8 px of
    the tip, or too little.
    """
    x, y = tip
    ring = np.ones_like(inside)
    ring[4:-4, 4:-4] = False
    ring &= inside
    if not ring.any():  # a frame smaller than the window: no background to measure the needle against
        raise TemplateError(
            f"no background around the tip ({x:g}, {y:g}) in the frame: the ring {params.half_window - 4} to "
            f"{params.half_window} px from it, where the background is read, lies wholly outside the frame"
        )
    smooth = ndimage.gaussian_filter(win, 1.0)
    level = float(np.median(smooth[ring]))
    spread = float(1.4826 * np.median(np.abs(smooth[ring] - level)))
    spread = max(spread, 0.3 * noise, 1e-12)
    dev = np.abs(smooth - level) / spread
    needle = dev > params.contrast
    labels, n = ndimage.label(needle)
    ox, oy = _offsets(params.half_window, apex)
    near = np.hypot(ox, oy) <= 8.0
    touching = set(np.unique(labels[near & needle]).tolist()) - {0}
    if not touching:
        raise TemplateError(
            f"nothing stands out from the background at the tip ({x:g}, {y:g}): no needle within 8 px "
            f"(it must stand {params.contrast:g} background spreads from the background level; the most there "
            f"stands {float(dev[near].max()):.1f}): {_WHAT_TO_DO}"
        )
    mask = np.isin(labels, list(touching))
    if mask.sum() < 12:
        raise TemplateError(
            f"too little of a needle at the tip ({x:g}, {y:g}): {int(mask.sum())} px stand out: {_WHAT_TO_DO}"
        )
    return np.asarray(mask), (level, spread)


def _passes_through(mask: NDArray[np.bool_], apex: tuple[float, float], h: int, within_deg: float) -> str | None:
    """Why the needle passes through the pixel given as its tip (it reaches the window's outer ring, 4 px wide, on
    two opposite sides: directions within ``within_deg`` of opposite, :attr:`TrackerParams.shaft_start_deg`), or
    ``None``.

    A pixel on the shaft learns a patch of two parallel edges: moved along its axis it looks the same, so every
    later fix stays near the first while the tip moves on (4 px a frame tracked as 0.4 px, with the score of a
    good fix). A tip's needle reaches the ring on one side only; blur and the rounded end stay within a few px.
    """
    ox, oy = _offsets(h, apex)
    dist = np.hypot(ox, oy)
    outer = mask & (dist >= h - 4) & (dist <= h)
    if int(outer.sum()) < 2:
        return None
    u = np.stack([ox[outer], oy[outer]]) / dist[outer]
    w, v = np.linalg.eigh(u @ u.T)  # the outer pixels' main direction through the pixel (either sense)
    p = v[:, -1] @ u
    lo, hi = float(p.min()), float(p.max())
    opposite = math.cos(math.radians(within_deg))
    if lo < -opposite and hi > opposite:
        back = v[:, -1] * (1 if float(p.mean()) >= 0 else -1)
        return (f"the needle continues beyond it, at least {h - 4} px towards ({-back[0]:+.2f}, {-back[1]:+.2f}) "
                f"and back; {_WHAT_TO_DO}")
    return None


def _level_weights(
    mask: NDArray[np.bool_], inside: NDArray[np.bool_], apex: tuple[float, float], params: TrackerParams
) -> list[FloatArray]:
    """The window's weights for each copy of the blur and sharpen banks: the needle, grown, near the tip."""
    h = params.half_window
    ox, oy = _offsets(h, apex)
    radial = np.exp(-0.5 * (ox**2 + oy**2) / (h * params.weight_falloff) ** 2)
    level_weights = []
    for b in (*params.blur_bank, *params.sharpen_bank):
        # a blurred tip spreads past the sharp one's edges and end: each copy's mask reaches 2 sigma further
        grown = _grown(mask, params.edge_px + int(round(2.0 * b)))
        soft = ndimage.gaussian_filter(grown.astype(float), 0.7)
        level_weights.append(np.clip(soft, 0.0, 1.0) * radial * inside)
    return level_weights


def _grown(mask: NDArray[np.bool_], steps: int) -> NDArray[np.bool_]:
    """``mask`` grown by ``steps`` pixels (none: ``mask`` itself; scipy's dilation by 0 iterations would grow it
    until nothing changes, the whole window)."""
    return mask if steps <= 0 else np.asarray(ndimage.binary_dilation(mask, iterations=steps))


def _surroundings(
    mask: NDArray[np.bool_], inside: NDArray[np.bool_], apex: tuple[float, float], params: TrackerParams
) -> tuple[tuple[float, float], Offsets, Offsets, Offsets]:
    """What the occlusion check compares the region in front of the tip with (offsets from the tip, px).

    The shaft's direction (a unit vector from the tip back along the needle), the needle's
    core near the tip, the background around it, and the background in front of the tip
    (within 60 deg of straight ahead, 2..14 px away).
    """
    h = params.half_window
    ox, oy = _offsets(h, apex)
    dist = np.hypot(ox, oy)
    near_mask = mask & (dist <= h)
    vx, vy = float(ox[near_mask].mean()), float(oy[near_mask].mean())
    norm = math.hypot(vx, vy)
    shaft = (vx / norm, vy / norm) if norm > 1e-9 else (1.0, 0.0)
    eroded = ndimage.binary_erosion(mask, iterations=1)
    core_pick = (eroded if eroded.sum() >= 4 else mask) & (dist >= 2.0) & (dist <= 10.0)
    wide = _grown(mask, params.edge_px + 2 * int(round(params.blur_bank[-1])))
    ring_sel = ~wide & (dist >= 6.0) & inside
    core = (ox[core_pick].astype(float), oy[core_pick].astype(float))
    ring_off = (ox[ring_sel].astype(float), oy[ring_sel].astype(float))
    ahead = (ox * shaft[0] + oy * shaft[1]) < -0.5 * dist
    grown2 = _grown(mask, params.edge_px + 1)
    front_sel = ahead & (dist >= 2.0) & (dist <= 14.0) & ~grown2 & inside
    front = (ox[front_sel].astype(float), oy[front_sel].astype(float))
    return shaft, core, ring_off, front


def _trackable_contrast(win: FloatArray, weights: FloatArray, noise: float, tip: tuple[float, float]) -> float:
    """The needle's weighted contrast (its standard deviation over ``weights``; image units).

    Raises :class:`TemplateError` when its signal to noise over the window is below 10.
    """
    x, y = tip
    sw = float(weights.sum())
    mean = float((weights * win).sum() / sw)
    contrast = math.sqrt(float((weights * (win - mean) ** 2).sum() / sw))
    snr = contrast / max(noise, 1e-12) * math.sqrt(sw)
    if snr < 10.0:
        raise TemplateError(
            f"the needle at ({x:g}, {y:g}) stands out by {contrast / max(noise, 1e-12):.2g} times the pixel noise "
            f"over {sw:.0f} px (signal to noise {snr:.1f} < 10): too faint to track; start with a frame in focus, "
            f"with more light or a longer exposure"
        )
    return contrast


@dataclass
class _KernelFFT:
    shape: tuple[int, int]
    w: NDArray[np.complex128]
    wt: NDArray[np.complex128]
    sw: float
    st2: float


def _kernel_fft(t: FloatArray, w: FloatArray, shape: tuple[int, int], single: bool = False) -> _KernelFFT:
    sw = float(w.sum())
    tc = t - float((w * t).sum() / sw)
    wt = w * tc
    fw = fft.rfft2(w[::-1, ::-1], shape, workers=1)
    fwt = fft.rfft2(wt[::-1, ::-1], shape, workers=1)
    if single:  # made in double precision, kept in single
        fw, fwt = fw.astype(np.complex64), fwt.astype(np.complex64)
    return _KernelFFT(shape, fw, fwt, sw, float((w * tc * tc).sum()))


def region_spectra(region: FloatArray, inside: FloatArray | None = None, single: bool = False,
                   shape: tuple[int, int] | None = None) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """The transforms of ``region`` and of its square that :func:`masked_ncc` needs (made once for several
    templates over the same region): both in one call, each the values it has alone.

    ``single``: in single precision (complex64, about half the work), of the region less its mean over
    ``inside`` (its pixels where ``inside`` is 1; all without it) there: the correlation is the same for any
    level added to the pixels it sums over, and the sums of squares about the mean lose less to rounding.
    ``shape``: the transforms' size (the region padded with zeros below and to the right; its own without).
    """
    if single:
        if inside is None:
            r = (region - float(region.mean())).astype(np.float32)
        else:
            level = float((region * inside).sum() / max(float(inside.sum()), 1.0))
            r = (region - level * inside).astype(np.float32)
        f = fft.rfft2(np.stack((r, r * r)), shape, workers=1)
    else:
        f = fft.rfft2(np.stack((region, region * region)), workers=1)
    return f[0], f[1]


_SHARED = ("shared variance",)
"""The key under which :func:`masked_ncc` keeps the last variance it made from given spectra."""


def _inverse(spectrum: NDArray[np.complex128], shape: tuple[int, int], start: int) -> FloatArray:
    """``scipy.fft.irfft2(spectrum, shape)[start:, start:]``, bit for bit, in about half its time.

    scipy's two-axis inverse is pocketfft's: the complex inverse down the columns unscaled, then
    the real inverse along each row, scaled there by ``1 / (rows x columns)`` (worked out in the
    C compiler's long double, one product per value). Here the same two passes, the rows before
    ``start`` dropped between them (the correlation keeps none of them), and the same scale
    after: the values the full transform gives the rows kept (``tests/test_vision_kernels.py``).
    Several spectra stacked (shape (k, rows, columns // 2 + 1)) are inverted in one call each
    pass, each the values it gives alone.
    """
    scale = float(np.longdouble(1.0) / np.longdouble(shape[0] * shape[1]))
    cols = fft.ifft(spectrum, shape[0], axis=-2, norm="forward", workers=1)[..., start:, :]
    out: FloatArray = fft.irfft(cols, shape[1], axis=-1, norm="forward", workers=1)[..., start:]
    out *= scale
    return out


def _variance(fi: NDArray[np.complex128], fi2: NDArray[np.complex128], k: _KernelFFT, n: int,
              shape: tuple[int, int]) -> FloatArray:
    """The weighted sum of squares about the weighted mean of the region under the window at every offset
    (``max(sum w I² - (sum w I)² / sum w, 0)``), from the region's spectra ``fi``, ``fi2`` (of it and its
    square) and the weights' transform in ``k``."""
    return _spread(_inverse(fi * k.w, shape, n - 1), _inverse(fi2 * k.w, shape, n - 1), k.sw)


def _spread(a: FloatArray, b: FloatArray, sw: float) -> FloatArray:
    """``max(b - a² / sw, 0)``: the weighted sum of squares about the weighted mean from the weighted sums of the
    values ``a`` and of their squares ``b`` and the weights' sum ``sw`` (in place of a new array, in this order)."""
    var: FloatArray = a * a
    var /= sw
    np.subtract(b, var, out=var)
    np.maximum(var, 0.0, out=var)
    return var


def _variance_and_sums(region: FloatArray, k: _KernelFFT, n: int, shape: tuple[int, int], single: bool = False
                       ) -> tuple[FloatArray, FloatArray]:
    """:func:`_variance` of ``region`` and its correlation with the template's centred weights (``sum w (T -
    T_w) I``), the region's two transforms and the three inverse ones stacked: each the values it has made
    alone (pocketfft transforms each line by itself), in fewer calls."""
    fi, fi2 = region_spectra(region, single=single, shape=None if shape == region.shape else shape)
    prod = np.empty((3, *fi.shape), dtype=fi.dtype)
    np.multiply(fi, k.w, out=prod[0])
    np.multiply(fi2, k.w, out=prod[1])
    np.multiply(fi, k.wt, out=prod[2])
    sums = _inverse(prod, shape, n - 1)[..., : region.shape[0] - n + 1, : region.shape[1] - n + 1]
    return _spread(sums[0], sums[1], k.sw), sums[2]


def masked_ncc(
    region: FloatArray, template: FloatArray, weights: FloatArray, cache: dict[object, object] | None = None,
    key: object = None, spectra: tuple[NDArray[np.complex128], NDArray[np.complex128]] | None = None,
    single: bool = False,
) -> FloatArray:
    """Weighted normalised cross-correlation of ``template`` at every offset inside ``region``.

    ``out[i, j]`` compares the template with ``region[i:i+n, j:j+n]`` (``n`` the template's
    side), each pixel weighted by ``weights``: ``sum w (T - T_w)(I - I_w) / sqrt(sum w (T -
    T_w)² · sum w (I - I_w)²)`` with ``T_w``, ``I_w`` the weighted means; in [-1, 1], 0 where
    the region is flat. By FFT (region and its square once each). ``cache`` (a dict the
    caller keeps for this template) holds the template's transforms under ``key``; ``spectra``
    are the region's own (:func:`region_spectra`) when the caller has them. With both, the
    region's variance under the weights is kept in ``cache`` and used again by the next call
    with the same ``spectra`` and ``weights`` objects (neither changed in place between calls).
    ``single``: the transforms in single precision (:func:`region_spectra`; ``spectra`` then made so), the
    values within about 1e-6 of double precision's where the window's spread is that of the region, within
    about ``1e-7 (region's / window's)²`` where it is smaller (a flat window: near 0, not 0); with the region's
    own transforms, at sizes pocketfft is quick at (:func:`scipy.fft.next_fast_len`, the region padded).
    """
    n = template.shape[0]
    rh, rw = region.shape
    shape = (rh, rw)
    tshape = (fft.next_fast_len(rh, True), fft.next_fast_len(rw, True)) if single and spectra is None else shape
    ck = (key, *tshape, single)
    k = cache.get(ck) if cache is not None else None
    if not isinstance(k, _KernelFFT):
        k = _kernel_fft(template, weights, tshape, single)
        if cache is not None:
            cache[ck] = k
    if spectra is None:  # the region's own: its two transforms and the three inverse ones each in one call
        var, c = _variance_and_sums(region, k, n, tshape, single)
    else:
        fi, fi2 = spectra
        # the region's weighted variance under the window depends on the weights, not the template: templates with
        # the same weights over the same spectra share it (the whole-frame search's blur copies)
        shared = cache.get(_SHARED) if cache is not None else None
        if isinstance(shared, tuple) and shared[0] is spectra and shared[1] is weights and shared[2] == (n, rh, rw):
            var = shared[3]
        else:
            var = _variance(fi, fi2, k, n, shape)
            if cache is not None:
                cache[_SHARED] = (spectra, weights, (n, rh, rw), var)
        c = _inverse(fi * k.wt, shape, n - 1)
    # c over sqrt(var st2) where that is above 1e-9 of its largest (0 elsewhere), clipped to [-1, 1]; in place
    denom = var * k.st2
    np.sqrt(denom, out=denom)
    scale = float(denom.max()) if denom.size else 0.0
    out = np.zeros(denom.shape)
    np.divide(c, denom, out=out, where=denom > 1e-9 * max(scale, 1e-300))
    np.maximum(out, -1.0, out=out)
    return np.minimum(out, 1.0, out=out)


@dataclass
class _InsideKernels:
    """The transforms of a template's weights ``w``, of ``w tc`` and of ``w tc²`` (``tc`` the template less its
    weighted mean) at one region size, and the weights' sum."""

    w: NDArray[np.complex128]
    wt: NDArray[np.complex128]
    wt2: NDArray[np.complex128]
    sw: float
    w_region: NDArray[np.complex128]  # ``w`` and ``wt`` as the region's spectra are multiplied by (single or double)
    wt_region: NDArray[np.complex128]


def _inside_kernels(t: FloatArray, w: FloatArray, shape: tuple[int, int], single: bool = False) -> _InsideKernels:
    sw = float(w.sum())
    tc = t - float((w * t).sum() / sw)
    spectra = [fft.rfft2(a[::-1, ::-1], shape, workers=1) for a in (w, w * tc, w * tc * tc)]
    fw, fwt = spectra[0], spectra[1]
    if single:
        fw, fwt = fw.astype(np.complex64), fwt.astype(np.complex64)
    return _InsideKernels(spectra[0], spectra[1], spectra[2], sw, fw, fwt)


_SHARED_INSIDE = ("shared inside sums",)
"""The key under which :func:`inside_ncc` keeps the region's sums it made from given spectra."""


def inside_ncc(
    region: FloatArray, inside: FloatArray, template: FloatArray, weights: FloatArray,
    cache: dict[object, object] | None = None, key: object = None,
    spectra: tuple[NDArray[np.complex128], NDArray[np.complex128]] | None = None, least: float = 0.0,
    single: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """:func:`masked_ncc` over the pixels of ``region`` that lie in the frame (``inside`` 1, else 0), and the
    share of the template's weight there at each offset.

    ``region`` is 0 outside the frame (a frame padded with zeros): at offset ``(i, j)`` the
    weights are ``weights · inside[i:i+n, j:j+n]``, so the template's weighted mean and
    spread, as the frame's, are taken over the part of it inside; a template hanging over
    the border is compared with what the frame shows of it (masked normalised
    cross-correlation). Every sum is a correlation with ``inside`` or with the region: six
    transforms in all, three of them (``inside`` against ``w``, ``w tc``, ``w tc²``)
    the same for every frame of a size, kept in ``cache`` with the ``inside`` they were
    made for (``inside`` not changed in place between calls). Offsets where less than
    ``least`` of the weight lies inside get 0. All inside, the values are
    :func:`masked_ncc`'s to rounding. ``single`` as :func:`masked_ncc`'s (the region's level taken
    over ``inside``; the template's sums over the part inside stay in double precision).

    Returns
    -------
    ncc, coverage : ndarray
        The correlation in [-1, 1] and the share of the weight inside (0..1), each of
        ``(rh - n + 1, rw - n + 1)`` offsets.
    """
    n = template.shape[0]
    rh, rw = region.shape
    shape = (rh, rw)
    ck = (key, rh, rw, "inside", single)
    k = cache.get(ck) if cache is not None else None
    if not isinstance(k, _InsideKernels):
        k = _inside_kernels(template, weights, shape, single)
        if cache is not None:
            cache[ck] = k
    # the template's sums over the part inside: kept with the inside they were made for (one per key)
    tk = (key, rh, rw, "inside terms")
    kept = cache.get(tk) if cache is not None else None
    if isinstance(kept, tuple) and (kept[0] is inside or np.array_equal(kept[1], inside)):
        inv_m0, ratio, vt, coverage = kept[2:]
    else:
        fm = fft.rfft2(inside, workers=1)
        m0, m1, m2 = (_inverse(fm * s, shape, n - 1) for s in (k.w, k.wt, k.wt2))
        inv_m0 = 1.0 / np.maximum(m0, 1e-300)
        ratio = m1 * inv_m0  # the template's weighted mean over the part inside (less its mean over all)
        vt = np.maximum(m2 - m1 * ratio, 0.0)
        coverage = np.clip(m0 / k.sw, 0.0, 1.0)
        if cache is not None:
            cache[tk] = (inside, inside.copy(), inv_m0, ratio, vt, coverage)
    fi, fi2 = region_spectra(region, inside, single) if spectra is None else spectra
    shared = cache.get(_SHARED_INSIDE) if cache is not None and spectra is not None else None
    if (isinstance(shared, tuple) and shared[0] is spectra and shared[1] is weights and shared[5] is inside
            and shared[2] == (n, rh, rw)):
        a, var = shared[3], shared[4]
    else:
        # the sum of w I over the part inside (I is 0 outside); in double precision from here (the template's sums'
        # reciprocals are large where little of it lies inside)
        a = _inverse(fi * k.w_region, shape, n - 1).astype(np.float64, copy=False)
        var = _inverse(fi2 * k.w_region, shape, n - 1).astype(np.float64, copy=False)
        var -= a * a * inv_m0
        np.maximum(var, 0.0, out=var)
        if cache is not None and spectra is not None:
            cache[_SHARED_INSIDE] = (spectra, weights, (n, rh, rw), a, var, inside)
    cov = _inverse(fi * k.wt_region, shape, n - 1).astype(np.float64, copy=False)
    cov -= a * ratio
    denom = var * vt
    np.sqrt(denom, out=denom)
    scale = float(denom.max()) if denom.size else 0.0
    out = np.zeros(denom.shape)
    ok = (denom > 1e-9 * max(scale, 1e-300)) & (coverage >= max(least, 1e-9))
    np.divide(cov, denom, out=out, where=ok)
    np.clip(out, -1.0, 1.0, out=out)
    return out, coverage
