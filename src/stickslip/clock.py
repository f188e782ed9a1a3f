"""One clock for the whole project: what "today" is, and how old a calibration is.

Definitions (stated once, used by every warning that compares dates):

* **Today** is the *local calendar date* of the machine that runs the command: the
  lab's working day, the one an operator writes on a session label. Set
  ``STICKSLIP_TODAY=YYYY-MM-DD`` to pin it (tests do; so can a user who replays an
  old session). Nothing else in the package reads the calendar.
* **Instants** stored in the database (``measured_at``, ``created``) are UTC, from
  :func:`now_utc`, so that a database moved between time zones keeps its order.
* **A calibration's age** is the number of calendar days from its session label
  (``day``, an ISO date) to today. A label that is not an ISO date (``day1``,
  ``morning``) has no age; it is compared with today's label for equality only.

The paper recalibrates every session because day-to-day changes are significant, so
a calibration is *stale* when its age exceeds ``max_age_days`` (default 0: any
earlier day). A calibration dated *ahead* of today by up to :data:`MAX_DAYS_AHEAD`
days was made on a machine in another time zone; further ahead, a clock (this
machine's or that one's) or the label is wrong, its age is unknown, and it is
warned about as well.
"""

from __future__ import annotations

import datetime as _dt
import os
import re

__all__ = [
    "max_age_days",
    "MAX_DAYS_AHEAD",
    "ENV_TODAY",
    "today",
    "today_label",
    "now_utc",
    "parse_day",
    "day_label_problem",
    "check_day_label",
    "age_days",
    "stale_message",
]

ENV_TODAY = "STICKSLIP_TODAY"
ENV_MAX_AGE = "STICKSLIP_MAX_AGE_DAYS"
"""Environment variable that pins :func:`today` (an ISO date, ``YYYY-MM-DD``)."""


def today() -> _dt.date:
    """Today's date: ``$STICKSLIP_TODAY`` if set, else the machine's local calendar date.

    Raises
    ------
    ValueError
        If ``$STICKSLIP_TODAY`` is set but is not an ISO date.
    """
    pinned = os.environ.get(ENV_TODAY, "").strip()
    if pinned:
        try:
            return _dt.date.fromisoformat(pinned)
        except ValueError:
            raise ValueError(f"{ENV_TODAY}={pinned!r} is not a date; use YYYY-MM-DD, e.g. 2026-11-23") from None
    return _dt.date.today()


_today = today  # for functions whose ``today`` parameter hides this one


def today_label() -> str:
    """Today's session label, the ISO date of :func:`today` (``"2026-11-23"``)."""
    return today().isoformat()


def now_utc() -> _dt.datetime:
    """The current instant, timezone-aware UTC (for timestamps stored in files and the database)."""
    return _dt.datetime.now(_dt.UTC)


def parse_day(label: str | None) -> _dt.date | None:
    """The date of a session label that starts with an ISO date (``2026-11-22``, ``2026-11-22 am``), else ``None``."""
    if not isinstance(label, str):
        return None
    try:
        return _dt.date.fromisoformat(label.strip()[:10])
    except ValueError:
        return None


_DATE_SHAPED = re.compile(r"\d{4}-\d+-\d+", re.ASCII)
MAX_LABEL_CHARS = 64
"""The longest session label accepted (a label is a key in tables and the database, not a note)."""


def day_label_problem(label: str, spreadsheet_dates: bool = True) -> str | None:
    """Why ``label`` cannot be a session label, or ``None`` if it can.

    A label is free text (``2026-11-22``, ``2026-11-22 pm``, ``day1``), but one that
    starts like a date must be a real ISO date: ``2026-13-45`` or ``2026-2-30`` is a
    typo, and would silently have no age (so no staleness warning) and sort apart from
    its session; so is one that starts with a date as a spreadsheet or MATLAB writes it
    (``22.11.2026``, ``11/22/2026``, ``22-Nov-2026``) unless ``spreadsheet_dates`` is False
    (a file written before that rule). A label is one line of printable text, at most
    :data:`MAX_LABEL_CHARS` characters.
    """
    text = label.strip()
    if not text:
        return "the session label is empty (use an ISO date, e.g. 2026-11-22)"
    if len(text) > MAX_LABEL_CHARS:
        return f"the session label is {len(text)} characters long (at most {MAX_LABEL_CHARS})"
    if not text.isprintable():
        bad = next(c for c in text if not c.isprintable())
        return (f"the session label {text[:MAX_LABEL_CHARS]!r} holds a control character or an invisible one "
                f"(U+{ord(bad):04X}: a tab, a line break, a zero-width space)")
    if spreadsheet_dates and (why := _other_date_problem(text)) is not None:
        return why
    shaped = _DATE_SHAPED.match(text)
    if shaped is not None:
        y, m, d = (int(x) for x in shaped.group(0).split("-"))
        try:
            date = _dt.date(y, m, d)
        except (ValueError, OverflowError) as e:
            return f"the session label {text!r} starts like a date but is not one ({e})"
        if shaped.group(0) != date.isoformat():
            return f"the session label {text!r}: write the date as {date.isoformat()} (YYYY-MM-DD)"
    return None


_NUMERIC_DATE = re.compile(r"(\d{1,2})([./])(\d{1,2})\2(\d{4}|\d{2})(?!\d)", re.ASCII)
_MONTH_DATE = re.compile(r"(\d{1,2})-([A-Za-z]{3})-(\d{4})(?!\d)", re.ASCII)
_MONTHS = ("jan", "feb", "mar", "apr", "may", "jun", "jul", "aug", "sep", "oct", "nov", "dec")


def _other_date_problem(text: str) -> str | None:
    """Why a label that starts with a date as a spreadsheet or MATLAB writes it (22.11.2026, 11/22/2026,
    22-Nov-2026) cannot be a session label: like an ISO typo it would have no age (no staleness warning) and sort
    apart from its session (22.11.2026 before 30.10.2026). ``None`` for any other label."""
    iso = None
    if (m := _NUMERIC_DATE.match(text)) is not None:
        if m.group(2) == "." and len(m.group(4)) == 4:  # day.month.year (German, Dutch): one reading
            iso = _iso(int(m.group(4)), int(m.group(3)), int(m.group(1)))
    elif (m := _MONTH_DATE.match(text)) is not None and m.group(2).lower() in _MONTHS:  # MATLAB's datetime
        iso = _iso(int(m.group(3)), _MONTHS.index(m.group(2).lower()) + 1, int(m.group(1)))
    else:
        return None
    as_iso = f"write it as {iso}" if iso else "write the date as YYYY-MM-DD"
    return (f"the session label {text!r} is a date as a spreadsheet writes it: {as_iso} (YYYY-MM-DD), so that it "
            "has an age and sorts with its session")


def _iso(y: int, m: int, d: int) -> str | None:
    try:
        return _dt.date(y, m, d).isoformat()
    except ValueError:
        return None


def check_day_label(label: str) -> str:
    """``label`` stripped, if it can be a session label (:func:`day_label_problem`); else ``ValueError``."""
    why = day_label_problem(label)
    if why is not None:
        raise ValueError(why)
    return label.strip()


def age_days(day: str | None, today: str | _dt.date | None = None) -> int | None:
    """Calendar days from session label ``day`` to ``today`` (default: :func:`today`); ``None`` if either is not a date.

    Negative when ``day`` is later than today (a calibration dated ahead of the clock).
    """
    a = parse_day(day)
    if today is None:
        b: _dt.date | None = _today()
    elif isinstance(today, _dt.date):
        b = today
    else:
        b = parse_day(today)
    if a is None or b is None:
        return None
    return (b - a).days


def max_age_days(value: int | None = None) -> int:
    """The largest age (days) of a calibration still used without a warning.

    ``value`` if given, else ``$STICKSLIP_MAX_AGE_DAYS``, else 0 (only today's calibration
    is fresh: the paper found the day-to-day changes significant).

    Raises
    ------
    ValueError
        If the value is not a whole number of days in 0..36500.
    """
    raw: object = value if value is not None else os.environ.get(ENV_MAX_AGE, "").strip() or 0
    try:
        days = int(str(raw))
    except ValueError:
        raise ValueError(f"${ENV_MAX_AGE} = {raw!r} is not a whole number of days") from None
    if not 0 <= days <= 36500:
        raise ValueError(f"the largest calibration age must be 0..36500 days, got {days}")
    return days


MAX_DAYS_AHEAD = 2
"""Most calendar days a label written elsewhere can be ahead of today: the local dates of two time zones
(UTC+14 and UTC-12) differ by at most two at any instant."""


def stale_message(cal_day: str | None, today: str | None = None, max_age_days: int = 0) -> str | None:
    """The recalibration warning for a calibration made on ``cal_day``, or ``None`` if it is fresh.

    Parameters
    ----------
    cal_day : str or None
        The calibration's session label. A calibration without one never warns.
    today : str, optional
        Today's session label (default :func:`today_label`).
    max_age_days : int
        Largest age in days that is still fresh (default 0: only today's calibration).

    Notes
    -----
    When both labels are ISO dates the warning comes only if the calibration is more
    than ``max_age_days`` older, or more than :data:`MAX_DAYS_AHEAD` days newer; other
    labels warn whenever they differ from today's, since their order is unknown.
    """
    if not cal_day:
        return None
    label = today_label() if today is None else today
    age = age_days(cal_day, label)
    if age is not None and age < -MAX_DAYS_AHEAD:
        return (
            f"calibration is from {cal_day}, today is {label} ({-age} days ahead, more than time zones "
            "explain): this machine's clock or the label is wrong, so its age is unknown; check the date "
            f"(or pin it with ${ENV_TODAY}=YYYY-MM-DD)"
        )
    stale = age > max_age_days if age is not None else cal_day.strip() != label.strip()
    if not stale:
        return None
    when = f"{age} day{'s' if age != 1 else ''} old" if age is not None else "from another session"
    return (
        f"calibration is from {cal_day}, today is {label} ({when}): recalibrate "
        "(the paper found day-to-day changes significant)"
    )
