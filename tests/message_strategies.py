"""hypothesis strategies for the rig protocol's messages (shared by the serial and CAN codec tests)."""

from __future__ import annotations

from hypothesis import strategies as st

from sashil.drivers.messages import EDGE_AGE_NONE, Command, Configure, Hello, RoadSpeed, Sample, Status, Version

I32 = st.integers(-(2**31), 2**31 - 1)
#: one encoder's last edge as the wire carries it: (age, direction), or none recently (EDGE_AGE_NONE, 0)
EDGE = st.one_of(st.tuples(st.integers(0, EDGE_AGE_NONE - 1), st.sampled_from((-1, 1))), st.just((EDGE_AGE_NONE, 0)))


def _sample(time_us: int, arm: int, road: int, current: float, flags: int, arm_edge: tuple, road_edge: tuple) -> Sample:
    return Sample(time_us, arm, road, current, flags, *arm_edge, *road_edge)


def messages(device_time_bits: int) -> st.SearchStrategy:
    """Any protocol message; a Sample's device time fits ``device_time_bits`` (32 serial, 24 CAN)."""
    return st.one_of(
        st.builds(
            _sample,
            st.integers(0, 2**device_time_bits - 1),
            I32,
            I32,
            st.floats(-16.0, 16.0),
            st.integers(0, 255),
            EDGE,
            EDGE,
        ),
        st.builds(Command, st.floats(0.0, 32.0), st.integers(0, 255)),
        st.builds(RoadSpeed, st.floats(-2000.0, 2000.0)),
        st.builds(Status, st.integers(0, 255), st.integers(0, 255), st.integers(0, 65535), st.integers(0, 65535)),
        st.builds(Hello, st.integers(0, 255)),
        st.builds(Version, st.integers(0, 255), st.integers(0, 2**32 - 1), st.floats(0.0, 32.0)),
        st.builds(Configure, st.integers(0, 65535), st.integers(0, 65535), st.integers(0, 1)),
    )
