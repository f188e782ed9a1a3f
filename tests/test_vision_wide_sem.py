"""A wide SEM tip the first frame does not learn (issue 30, track72; docs/vision-log.md, "A wide SEM tip refused on
its first frame").

The reproduction's sequence 219: an SEM needle 18.6 px wide, sharp (blur 0.09 px), plain to see. Its shaft crosses
the window's ring, where the background's level and spread are read: a quarter of the ring is needle, the ring's
spread is 0.093 where the ground's own (the needle left out) is 0.069, and the body, 0.2 above the ground, stands
2.4 spreads out. The refusal says what to do.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from vision_own import own_sequence

from stickslip.vision.frame import as_image
from stickslip.vision.template import TemplateError, TipTemplate


@lru_cache(maxsize=1)
def _first_frame() -> tuple[np.ndarray, tuple[float, float]]:
    """The reproduction's SEM sequence 219's first frame and its tip (x, y; px)."""
    frame = own_sequence(1219, 1, width_px=18.59031767576416, look="sem", max_blur=3.0).frames[0]
    return as_image(frame.image), frame.tip


def test_a_wide_sem_tip_is_refused_with_what_to_do() -> None:
    image, tip = _first_frame()
    with pytest.raises(TemplateError) as e:
        TipTemplate.learn(image, tip)
    message = str(e.value)
    assert "nothing stands out" in message
    assert "the most there stands 2.4" in message  # 3 needed
    assert "put the tip on the needle's very end, or start with a frame in focus" in message
    assert "\n" not in message

