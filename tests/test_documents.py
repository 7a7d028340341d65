"""Progress documents: the engine tells a verb's subscribers how each run of a set goes, in order,
between that run's start and its stop."""

from __future__ import annotations

from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.lab._drop_test import run_drop_test
from sashil.writer.documents import Documents


def test_each_drop_of_a_set_reports_its_progress_between_its_start_and_its_stop():
    config = resolve(ConfigSource(options=(Option("--duration", "drop_test.duration_s", 0.4),)), "drop-test")
    seen: list[tuple[str, str | None, str]] = []
    cycles: list[int] = []

    def subscriber(kind, fields):
        seen.append((kind, fields.get("run"), fields.get("text", "")))
        if kind == "stop":
            cycles.append(fields["record"].summary["timing"]["cycles"])

    documents = Documents([subscriber])
    for current in (0.0, 0.5):
        run_drop_test(config, -5.0, current, 0.4, documents=documents, name=f"i{current:.3f}A", recorded_config=config)
    assert [(kind, run) for kind, run, _ in seen] == [
        ("start", "i0.000A"),
        ("progress", "i0.000A"),
        ("progress", "i0.000A"),
        ("stop", "i0.000A"),
        ("start", "i0.500A"),
        ("progress", "i0.500A"),
        ("progress", "i0.500A"),
        ("stop", "i0.500A"),
    ]
    running, ran = seen[1][2], seen[2][2]
    assert running == "running: sim backend, the loop in this process on simulated time, until its plan ends at 1000 Hz"
    # the loop's cycles, as its stop document counts them: the hold, then 0.4 s after the release
    assert ran == f"ran: {cycles[0]} cycles ({cycles[0] / 1000:g} s of run time), ok" and cycles[0] > 400
