"""Bad input: any CSV content through what ``identify`` and ``calibrate`` read.

Every file either loads into finite, strictly time-ordered records or is refused with one
DataFileError line naming the file: never a traceback, a NaN in a record, or a hang."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sashil.errors import DataFileError
from sashil.identify.data import MIN_SAMPLES, load_records

NAMES = ["time_s", "theta_rad", "current_a", "theta_road_rad", "torque_in_nm", "x"]
CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.sampled_from(["", "nan", "inf", "-inf", "1e300", "-1e308", "0x10", "1,5", " 2 ", "\u00e9", "\x00", "1e-320"]),
)


@st.composite
def csv_text(draw: st.DrawFn) -> str:
    if draw(st.booleans()):  # plausible: a record that loads unless a drawn cell or the time base spoils it
        header = ["time_s", "theta_rad", "current_a", *draw(st.lists(st.sampled_from(NAMES), max_size=3, unique=True))]
        header = list(dict.fromkeys(header))
        n = draw(st.sampled_from([0, 1, MIN_SAMPLES - 1, *[MIN_SAMPLES + 1500] * 3]))
        dt = draw(st.sampled_from([*[1e-3] * 6, 0.0, -1e-3, 1e-9, 1e300]))
        spoil = draw(st.one_of(st.none(), st.integers(0, max(n - 1, 0))))  # one bad cell somewhere, or none
        rows = []
        for k in range(n):
            cells = []
            for name in header:
                if k == spoil and name != "time_s":
                    cells.append(draw(CELLS))
                elif name == "time_s":
                    cells.append(repr(k * dt))
                else:
                    cells.append(repr(float(0.05 * np.exp(-k * 1e-3) * np.cos(k * 0.01))))
            rows.append(",".join(cells))
    else:  # anything
        header = draw(st.lists(st.sampled_from(NAMES), min_size=0, max_size=6))
        rows = [",".join(draw(st.lists(CELLS, min_size=0, max_size=7))) for _ in range(draw(st.integers(0, 30)))]
    return "\n".join([",".join(header), *rows]) + draw(st.sampled_from(["", "\n", "\n\n", "\r\n"]))


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@given(text=csv_text())
def test_any_csv_loads_clean_or_is_one_line_naming_the_file(tmp_path, text):
    path = tmp_path / "data.csv"
    path.write_text(text, encoding="utf-8")
    try:
        records = load_records([path])
    except DataFileError as err:
        message = str(err)
        assert message.startswith(str(path)) and "\n" not in message
        return
    for record in records:
        for values in (
            record.time_s,
            record.theta,
            record.current,
            record.acc_road,
            record.theta_dot,
            record.theta_ddot,
        ):
            assert np.all(np.isfinite(values))
        assert np.all(np.diff(record.time_s) > 0)
