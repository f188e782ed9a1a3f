"""The day the test suite pins as "today" (``$STICKSLIP_TODAY``), shared by conftest and the generators."""

PINNED_TODAY = "2026-11-22"
