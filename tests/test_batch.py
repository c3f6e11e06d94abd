"""`roadview batch` on Dask: a local cluster, a real scheduler and workers, a worker killed."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from distributed import Client

from tests.helpers import interruptible, read_record, run_cli


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory, data_dir: Path) -> Path:
    """The three shared clips and a corrupt one, in a folder with a subfolder."""
    folder = tmp_path_factory.mktemp("inputs")
    (folder / "sub").mkdir()
    for name in ("test_video", "project_cut_1"):
        (folder / f"{name}.mp4").write_bytes((data_dir / "videos" / f"{name}.mp4").read_bytes())
    cut2 = (data_dir / "videos" / "project_cut_2.mp4").read_bytes()
    (folder / "sub" / "project_cut_2.mp4").write_bytes(cut2)
    test_video = (data_dir / "videos" / "test_video.mp4").read_bytes()
    (folder / "broken.mp4").write_bytes(test_video[:2_000])  # the index, no whole frame
    return folder


def _batch(inputs: Path, out: Path, *options: str) -> list[str]:
    """The command line of `roadview batch INPUTS --out OUT OPTIONS`."""
    return [sys.executable, "-m", "app", "batch", str(inputs), "--out", str(out), *options]


def _manifest(out: Path) -> dict[str, dict[str, object]]:
    return {
        Path(str(r["path"])).name: r
        for r in pq.read_table(out / "table/manifest.parquet").to_pylist()
    }


def test_local_cluster_three_done_one_failed_then_all_skipped(
    inputs: Path, data_dir: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    result = run_cli("batch", inputs, "--out", out, "--workers", "2", "--no-video")
    assert result.returncode == 1, result.stderr  # one input failed
    assert "3 done, 1 failed, 0 skipped" in result.stdout
    rows = _manifest(out)
    assert {n: r["status"] for n, r in rows.items()} == {
        "test_video.mp4": "done",
        "project_cut_1.mp4": "done",
        "project_cut_2.mp4": "done",
        "broken.mp4": "failed",
    }
    assert "no frame of it decodes" in str(rows["broken.mp4"]["error"])
    assert rows["project_cut_2.mp4"]["frames"] == 88
    assert abs(float(rows["project_cut_2.mp4"]["video_seconds"]) - 3.52) < 0.01  # type: ignore[arg-type]
    # Outputs mirror the inputs' relative paths; records equal those of `roadview process`.
    record = out / "sub" / "project_cut_2.jsonl"
    alone = tmp_path / "alone.jsonl"
    single = run_cli(
        "process",
        data_dir / "videos" / "project_cut_2.mp4",
        "-o",
        tmp_path / "a.mp4",
        "--json",
        alone,
    )
    assert single.returncode == 0, single.stderr
    assert record.read_text() == alone.read_text()
    frames = pq.read_table(out / "table" / "frames").to_pylist()
    vehicles = pq.read_table(out / "table" / "vehicles").to_pylist()
    assert len(frames) == 38 + 76 + 88
    lines = read_record(record)
    assert sum(1 for f in frames if f["video"] == "sub/project_cut_2.mp4") == len(lines)
    assert sum(1 for v in vehicles if v["video"] == "sub/project_cut_2.mp4") == sum(
        len(r["vehicles"]) for r in lines
    )
    assert not list(out.rglob("*.tmp*"))
    # The README's queries work on the table.
    table = ds.dataset(out / "table" / "frames").to_table()
    ranked = table.group_by("video").aggregate([("vehicles", "mean")])
    ranked = ranked.sort_by([("vehicles_mean", "descending")]).to_pylist()
    assert {r["video"] for r in ranked} == {f["video"] for f in frames}
    assert 0.0 <= 1 - pc.mean(table["lane_found"].cast("int8")).as_py() <= 1.0
    tracked = ds.dataset(out / "table" / "vehicles").to_table()
    tracked = tracked.group_by("video").aggregate([("id", "count_distinct")]).to_pylist()
    by_video = {r["video"]: r["id_count_distinct"] for r in tracked}
    assert by_video["sub/project_cut_2.mp4"] == len({v["id"] for r in lines for v in r["vehicles"]})
    # The facts are in the tables as in the record; the events table exists (no event here).
    speeds = [f["speed_kmh"] for f in frames if f["video"] == "sub/project_cut_2.mp4"]
    assert speeds == [r["speed_kmh"] for r in lines]
    for column in ("road_grey", "horizon_y", "ground_scale"):
        values = [f[column] for f in frames if f["video"] == "sub/project_cut_2.mp4"]
        assert values == [r[column] for r in lines], column
    assert not any(f["rear"] for f in frames)  # front cameras all
    assert all(f["roll_deg"] == 0 for f in frames)  # level pictures all
    assert all(f["rotate_deg"] == 0 for f in frames)  # upright as stored all
    assert all(f["focal_mm"] is None for f in frames)  # the shipped calibration gave the lens
    assert {v["lane"] for v in vehicles} <= {"ego", "left", "right", "other"}
    events = ds.dataset(out / "table" / "events").to_table()
    assert events.num_rows == 0 and "vehicle_id" in events.column_names
    events.group_by(["video", "kind"]).aggregate([("kind", "count")])
    # A part that an older roadview wrote without a column is rewritten from the record when
    # its input is skipped, so that every part has the same columns.
    part = next((out / "table" / "frames").glob("*.parquet"))
    written = pq.read_table(part)
    pq.write_table(written.drop_columns(["roll_deg"]), part)
    again = run_cli("batch", inputs, "--out", out, "--workers", "2", "--no-video")
    assert "0 done, 1 failed, 3 skipped" in again.stdout, again.stdout
    assert pq.read_table(part).equals(written)
    # Other settings make other outputs: an input done with them is done again, not skipped.
    smaller = run_cli("batch", inputs, "--out", out, "--workers", "2", "--no-video",
                      "--max-size", "360")  # fmt: skip
    assert "3 done, 1 failed, 0 skipped" in smaller.stdout, smaller.stdout
    assert {tuple(r["size"]) for r in read_record(record)} == {(640, 360)}
    assert len({r["settings"] for r in _manifest(out).values()}) == 1


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _parent(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _worker_running_ffmpeg(ancestors: set[int]) -> int | None:
    """The pid of a Dask worker (a descendant of `ancestors`, the test's own processes) whose
    child is an ffmpeg decoding frames: a worker at work. Nothing else on the machine is touched."""
    for proc in Path("/proc").iterdir():
        try:
            args = (proc / "cmdline").read_bytes().split(b"\0")
            if not (args and b"ffmpeg" in args[0] and b"rawvideo" in args):
                continue
            worker = _parent(int(proc.name))
            pid = worker
            while pid > 1:
                if pid in ancestors:
                    return worker
                pid = _parent(pid)
        except (OSError, ValueError, IndexError):
            continue
    return None


def test_real_scheduler_and_a_worker_killed_mid_run(inputs: Path, tmp_path: Path) -> None:
    bin_dir = Path(sys.executable).parent
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = (tmp_path / "scheduler.log").open("w")
    procs = [
        subprocess.Popen(
            [
                str(bin_dir / "dask"),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--dashboard-address",
                ":0",
            ],
            stdout=logs,
            stderr=logs,
        )
    ]
    try:
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        str(bin_dir / "dask"),
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-nanny" if False else "--nanny",
                    ],
                    stdout=logs,
                    stderr=logs,
                )
            )
        # The batch starts once the scheduler has both workers (a fixed wait was too short
        # once, on a busy machine: the batch found no worker at work within a minute).
        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "out"
        batch = subprocess.Popen(
            _batch(inputs, out, "--scheduler", address, "--no-video"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        # Kill one worker's process while it works on a video: Dask retries the task elsewhere.
        deadline = time.time() + 60
        killed = False
        while time.time() < deadline and not killed:
            worker = _worker_running_ffmpeg({p.pid for p in procs})
            if worker is not None:
                os.kill(worker, signal.SIGKILL)
                killed = True
            time.sleep(0.1)
        stdout, stderr = batch.communicate(timeout=300)
        assert killed, stdout + stderr
        assert "3 done, 1 failed" in stdout, stdout + stderr
        rows = _manifest(out)
        assert sum(r["status"] == "done" for r in rows.values()) == 3
        assert not list(out.rglob("*.tmp*"))
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        logs.close()


def test_ctrl_c_keeps_what_finished_and_the_next_run_resumes(inputs: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    command = _batch(inputs, out, "--workers", "1", "--no-video")
    batch = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=interruptible,
    )
    manifest = out / "table" / "manifest.parquet"
    deadline = time.time() + 120
    while time.time() < deadline and not manifest.exists():
        time.sleep(0.05)
    assert manifest.exists(), "no input finished in time"
    batch.send_signal(signal.SIGINT)
    stdout, stderr = batch.communicate(timeout=120)
    assert batch.returncode == 130, stdout + stderr
    assert "interrupted" in stderr and "run the same command again to resume" in stderr
    kept = {n for n, r in _manifest(out).items() if r["status"] in ("done", "failed")}
    assert 1 <= len(kept) < 4
    assert not list(out.rglob("*.tmp*"))
    again = run_cli("batch", inputs, "--out", out, "--workers", "1", "--no-video")
    done_before = sum(1 for n in kept if n != "broken.mp4")
    assert f"{3 - done_before} done, 1 failed, {done_before} skipped" in again.stdout, again.stdout


def test_events_table_holds_each_event(tmp_path: Path) -> None:
    from app.batch import write_table_parts
    from app.events import Event, event_record

    event = Event("close_following", 10, 84, 0.4, 3.36, 7, 0.7)
    write_table_parts(tmp_path, "k", "a/b.mp4", [], [event_record(event)])
    (row,) = pq.read_table(tmp_path / "events").to_pylist()
    assert row == {"video": "a/b.mp4"} | event_record(event)


def test_frames_table_says_which_frames_a_rear_camera_saw(tmp_path: Path) -> None:
    from app.batch import write_table_parts

    lines: list[dict[str, Any]] = [{"frame": k, "time_s": k / 25, "lane": None} for k in range(3)]
    lines[2]["facing"] = "rear"  # the record says so once the road is seen moving away
    write_table_parts(tmp_path, "k", "rear.mp4", lines)
    rows = pq.read_table(tmp_path / "frames").to_pylist()
    assert [r["rear"] for r in rows] == [False, False, True]


def test_a_clip_of_another_camera_is_done_without_undistortion(
    test_video: Path, tmp_path: Path
) -> None:
    """As `process` does: a 4:3 clip is not the shipped 16:9 dashcam's, so by default it is
    processed without undistortion rather than failed."""
    from app.sources import ffmpeg_binary

    folder = tmp_path / "in"
    folder.mkdir()
    clip = folder / "square.mp4"
    scale = ["-vf", "scale=640:480,setsar=1", "-t", "0.4"]
    command = [ffmpeg_binary(), "-loglevel", "error", "-i", str(test_video), *scale, str(clip)]
    subprocess.run(command, check=True)
    out = tmp_path / "out"
    result = run_cli("batch", folder, "--out", out, "--workers", "1", "--no-video")
    assert result.returncode == 0, result.stderr
    assert "1 done, 0 failed" in result.stdout
    assert read_record(out / "square.jsonl")[0]["size"] == [640, 480]
    # What `process` would say of it is in its manifest row.
    import pyarrow.parquet as pq

    (row,) = pq.read_table(out / "table" / "manifest.parquet").to_pylist()
    assert "square.mp4" in row["notes"] and "without undistortion" in row["notes"], row
