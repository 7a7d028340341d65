"""sashil's pytest plugin (entry point ``sashil`` in the group ``pytest11``): the fixture
``sashil_rig`` and the option ``--sashil-seed``.

``sashil_rig`` is a :class:`sashil.testing.SimRig` whose runs go in the test's ``tmp_path``, with the
noise seed of ``--sashil-seed`` (default 0). A test changes the damper or the noise with
``dataclasses.replace(sashil_rig, damper={"c2": 2.0})``. Nothing of sashil's numerics loads until a
test asks for the fixture.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from sashil.testing.rig import SimRig


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("sashil", "sashil's simulated rig")
    group.addoption(
        "--sashil-seed",
        type=int,
        default=0,
        help="noise seed of the sashil_rig fixture's simulated rig (default 0)",
    )


@pytest.fixture(scope="session")
def sashil_warm() -> None:
    """Once per session: what a process's first run loads late (:func:`sashil.testing.rig.warm_up`),
    so a test's own time is its run's."""
    from sashil.testing.rig import warm_up

    warm_up()


@pytest.fixture
def sashil_rig(request: pytest.FixtureRequest, tmp_path: Path, sashil_warm: None) -> SimRig:
    """The simulated rig on the virtual clock, seeded by ``--sashil-seed``, its runs in ``tmp_path``."""
    from sashil.testing.rig import SimRig

    return SimRig(seed=int(request.config.getoption("--sashil-seed")), out=tmp_path / "runs")
