"""The threaded recorder: rows on disk in order, never blocking, crash-safe after SIGKILL."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np

from sashil.recording.data_file import read_data_csv
from sashil.recording.recorder import Recorder

COLUMNS = ("time_s", "theta_rad", "current_a", "current_cmd_a", "seq", "trip_code")


def fill(recorder, n, start=0):
    for k in range(start, start + n):
        row = recorder.begin_row()
        row[0], row[1], row[2], row[3], row[4], row[5] = k * 1e-3, 0.1 * k, 0.5, 0.5, k, 0
        recorder.commit_row()


def test_rows_reach_the_file_in_order(tmp_path):
    path = tmp_path / "data.csv"
    with Recorder(path, COLUMNS, capacity=64) as recorder:
        for chunk in range(10):  # more rows than the ring holds, handed over in chunks
            fill(recorder, 50, start=50 * chunk)
            while recorder.rows_committed - recorder.rows_written > 0:
                recorder._stop.wait(0.001)
    data = read_data_csv(path, required=COLUMNS)
    assert data["seq"].tolist() == list(range(500))
    assert data["theta_rad"][7] == 0.1 * 7  # repr: exact round trip
    assert path.read_text().splitlines()[2] == "0.001,0.1,0.5,0.5,1,0"
    assert recorder.rows_dropped == 0


def test_a_kept_stream_holds_the_values_the_file_parses_back_to(tmp_path):
    """keep=True: every row in memory as well (more than the ring's capacity, none dropped), and its
    columns equal, bit for bit, what the file's text parses back to; without a file, no thread."""
    path = tmp_path / "data.csv"
    recorder = Recorder(path, COLUMNS, capacity=16, lossless=True, keep=True).start()
    fill(recorder, 300)
    recorder.close()
    kept, parsed = recorder.stream(), read_data_csv(path, required=COLUMNS)
    assert list(kept) == list(COLUMNS) and recorder.rows_dropped == 0 and recorder.rows_written == 300
    for name in COLUMNS:
        assert kept[name].dtype == parsed[name].dtype and kept[name].tobytes() == parsed[name].tobytes(), name
    memory = Recorder(None, COLUMNS, keep=True).start()
    assert memory._thread is None
    fill(memory, 5)
    row = memory.begin_row()  # begun, never committed: not in the stream
    row[0] = 99.0
    memory.close()
    assert memory.stream()["seq"].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert {name: values.size for name, values in Recorder(None, COLUMNS, keep=True).stream().items()} == dict.fromkeys(
        COLUMNS, 0
    )


def test_a_full_ring_drops_and_counts_instead_of_blocking(tmp_path):
    recorder = Recorder(tmp_path / "data.csv", COLUMNS, capacity=16)
    fill(recorder, 20)  # the writer is not running: the ring fills up
    assert recorder.rows_committed == 16 and recorder.rows_dropped == 4
    recorder.start()
    recorder.close()
    assert read_data_csv(tmp_path / "data.csv", required=COLUMNS)["seq"].tolist() == list(range(16))


def test_closed_window_delays_the_writer_but_close_writes_everything(tmp_path):
    recorder = Recorder(tmp_path / "data.csv", COLUMNS, capacity=128, flush_interval_s=1.0).start()
    recorder.window_end_ns = 0  # the loop never sleeps: the writer must not start a slice at once ...
    fill(recorder, 10)
    assert recorder.rows_written == 0  # (its first chance to write is 3 flush intervals away)
    recorder.close()  # ... but close() drains it
    assert recorder.rows_written == 10


def test_a_window_that_stays_closed_still_gets_the_rows_written_within_a_second(tmp_path):
    # under load the loop never sleeps long enough for a slice: the writer writes anyway once rows
    # have waited 3 flush intervals (the "at least once a second" promise); it used to reset its
    # flush clock while it had nothing formatted, and so never wrote until close()
    recorder = Recorder(tmp_path / "data.csv", COLUMNS, capacity=128, flush_interval_s=0.05).start()
    recorder.window_end_ns = 0
    fill(recorder, 10)
    for _ in range(500):  # up to 5 s for a writer due after 0.15 s (a loaded machine is slow, not wrong)
        if recorder.rows_written == 10:
            break
        recorder._stop.wait(0.01)
    written = recorder.rows_written
    on_disk = len((tmp_path / "data.csv").read_text().splitlines()) - 1
    recorder.close()
    assert written == 10 and on_disk == 10


def test_data_survives_sigkill_mid_run(tmp_path):
    """Killed while rows keep coming: the file parses, and holds a gap-free prefix of the rows."""
    path = tmp_path / "data.csv"
    script = textwrap.dedent(
        f"""
        import sys, time
        from sashil.recording.recorder import Recorder
        rec = Recorder({str(path)!r}, {COLUMNS!r}, flush_interval_s=0.05).start()
        print("started", flush=True)
        k = 0
        while True:
            row = rec.begin_row()
            row[0], row[1], row[2], row[3], row[4], row[5] = k * 1e-3, 0.25, 0.5, 0.5, k, 0
            rec.commit_row()
            k += 1
            if k % 10 == 0:
                time.sleep(0.001)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "started"
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and (not path.exists() or path.stat().st_size < 20_000):
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(timeout=30) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
    data = read_data_csv(path, required=COLUMNS)
    n = len(data["seq"])
    assert n > 500
    assert data["seq"].tolist() == list(range(n))
    assert path.read_bytes().endswith(b"\n")  # whole lines only


def test_a_kept_stream_reads_whole_numbers_as_floats_and_a_missing_signal_as_nan():
    """The kept rows hold the sample's integers (seq, edge times) and may hold a stage signal of None:
    the columns are floats, None a NaN, as numpy would read them."""
    recorder = Recorder(None, ("time_s", "seq", "z_hat"), keep=True).start()
    for k, value in enumerate((0.5, None, 2)):
        row = recorder.begin_row()
        row[:] = [k * 1e-3, k, value]
        recorder.commit_row()
    recorder.close()
    stream = recorder.stream()
    assert stream["seq"].dtype == np.float64 and stream["seq"].tolist() == [0.0, 1.0, 2.0]
    assert stream["z_hat"][0] == 0.5 and math.isnan(stream["z_hat"][1]) and stream["z_hat"][2] == 2.0
    numbers = Recorder(None, ("time_s", "seq"), keep=True).start()
    for k in range(3):
        numbers.begin_row()[:] = [k * 0.1, k]
        numbers.commit_row()
    assert numbers.stream()["time_s"].tobytes() == np.array([0.0, 0.1, 0.2]).tobytes()
