"""`roadview report`: a self-contained page of plots and events, checked in headless Chromium."""

from __future__ import annotations

import base64
import html.parser
import json
import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from app.errors import InputError
from app.events import Event, event_record
from app.report import record_series, report_html, svg_plot
from tests.helpers import assert_one_line_error, process_clip, run_cli

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--virtual-time-budget=5000",
]


def _chromium() -> str:
    """Debian's Chromium (CI installs it and sets ROADVIEW_REQUIRE_BROWSER; elsewhere the
    browser test is skipped when there is none)."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        if os.environ.get("ROADVIEW_REQUIRE_BROWSER"):
            pytest.fail("ROADVIEW_REQUIRE_BROWSER is set but no chromium is installed")
        pytest.skip("no chromium: apt-get install chromium to run the browser test")
    return found


def _rows(n: int = 50) -> list[dict[str, Any]]:
    """A synthetic record: speed known after frame 5, the lane lost in frames 20-24, a car
    ahead closing from 30 m in frames 10-39."""
    rows = []
    for k in range(n):
        row: dict[str, Any] = {"frame": k, "time_s": k / 25, "size": [640, 360]}
        row["speed_kmh"] = 90.0 if k >= 5 else None
        row["lane"] = (
            None
            if 20 <= k < 25
            else {"left": [], "right": [], "curvature_m": None, "offset_m": 0.1, "width_m": 3.6}
        )
        row["vehicles"] = (
            [{"id": 3, "box": [300, 200, 340, 230], "lane": "ego", "distance_m": 30.0 - k / 5}]
            if 10 <= k < 40
            else []
        )
        rows.append(row)
    return rows


def test_plots_follow_the_record_with_gaps_where_nothing_was_measured() -> None:
    times, series = record_series(_rows())
    assert [s.key for s in series] == ["speed", "offset", "curvature", "distance", "vehicles"]
    by_key = {s.key: s for s in series}
    assert np.isnan(by_key["speed"].values[:5]).all() and (by_key["speed"].values[5:] == 90).all()
    assert np.isnan(by_key["offset"].values[20:25]).all()
    assert (by_key["curvature"].values[:20] == 0).all()  # a null radius: straight
    # The lane is lost once: the offset is drawn as two lines; the distance as one.
    assert svg_plot(times, by_key["offset"]).count("<polyline") == 2
    assert svg_plot(times, by_key["distance"]).count("<polyline") == 1
    no_lane = [{k: v for k, v in r.items() if k != "lane"} for r in _rows()]
    assert "offset" not in {s.key for s in record_series(no_lane)[1]}
    event = Event("close_following", 10, 39, 0.4, 1.56, 3, 0.9)
    page = report_html("t", _rows(), [event], {}, "test")
    assert page.count('class="span"') == 5  # the event shaded on every plot
    assert "close following" in page and "no video given" in page
    assert "1 vehicle tracked, up to 1 in view at once" in page
    two = _rows()
    two[12]["vehicles"] = [*two[12]["vehicles"], {"id": 4, "box": [500, 200, 540, 230]}]
    assert "2 vehicles tracked, up to 2 in view at once" in report_html("t", two, [], {}, "t")
    # A rear camera's record: the vehicle in our lane is behind us.
    rear = [{**r, "facing": "rear"} for r in _rows()]
    page = report_html("t", rear, [], {}, "test")
    assert "Distance to the vehicle behind" in page and "Vehicle behind" in page
    assert "vehicle ahead" not in page.lower()


class _Resources(html.parser.HTMLParser):
    """Every src/href of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.links += [v or "" for k, v in attrs if k in ("src", "href")]


@pytest.mark.slow
def test_report_renders_in_a_real_browser(test_video: Path, tmp_path: Path) -> None:
    """The page of a real clip's record, with an event on its tracked car, opens in headless
    Chromium: every plot is drawn, the thumbnail decodes, and nothing is fetched from outside."""
    browser = _chromium()
    records = process_clip(test_video, tmp_path)
    seen = [r["frame"] for r in records if any(v["id"] == 1 for v in r["vehicles"])]
    assert len(seen) > 20
    events = tmp_path / "e.jsonl"
    event = Event("close_following", seen[0], seen[20], seen[0] / 25, seen[20] / 25, 1, 0.8)
    events.write_text(json.dumps(event_record(event)) + "\n")
    page = tmp_path / "report.html"
    done = run_cli(
        "report", tmp_path / "r.jsonl", "--events", events, "--video", test_video, "-o", page
    )
    assert done.returncode == 0, done.stderr
    assert "1 events" in done.stdout

    parser = _Resources()
    parser.feed(page.read_text())
    assert parser.links and all(link.startswith("data:image/jpeg;base64,") for link in parser.links)

    profile = tmp_path / "profile"
    dom = subprocess.run(
        [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    # Every plot with a measured value is drawn (test_video's car is in the lane to our right:
    # no distance to a vehicle ahead).
    _, series = record_series(records)
    measured = [s.key for s in series if np.isfinite(s.values).any()]
    assert len(series) == 5 and "distance" not in measured
    assert re.search(rf'data-plots-drawn="{len(measured)}"', dom), dom[:300]
    assert re.search(r'data-thumbnails-shown="1"', dom), dom[:300]
    shot = tmp_path / "shot.png"
    subprocess.run(
        [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--screenshot={shot}",
         "--window-size=1000,2000", page.as_uri()],
        capture_output=True, timeout=120, check=True,
    )  # fmt: skip
    picture = cv2.imread(str(shot))
    assert picture is not None and picture.shape[:2] == (2000, 1000)
    # The plots' blue lines and the thumbnail's road (not white) are on the screen.
    blue = (picture[..., 0] > 150) & (picture[..., 2] < 80)
    assert blue.sum() > 2000
    assert (picture.std(axis=2) + np.abs(picture.mean(axis=2) - 255) > 30).mean() > 0.05


def test_report_problems_are_one_line(tmp_path: Path, test_video: Path) -> None:
    record = tmp_path / "r.jsonl"
    assert_one_line_error(run_cli("report", record), "cannot read record")
    record.write_text('{"frame": 0, "time_s": 0.0, "size": [1280, 720]}\n')
    assert_one_line_error(run_cli("report", record, "-o", record), "not an .html name")
    page = tmp_path / "r.html"
    bad = tmp_path / "e.jsonl"
    bad.write_text('{"kind": "sneezing"}\n')
    assert_one_line_error(run_cli("report", record, "--events", bad, "-o", page), "not an event")
    small = tmp_path / "small.jsonl"
    small.write_text('{"frame": 0, "time_s": 0.0, "size": [480, 360]}\n')  # not the video's
    events = tmp_path / "ok.jsonl"
    events.write_text(json.dumps(event_record(Event("closing_fast", 0, 0, 0.0, 0.0, 1, 2.0))))
    assert_one_line_error(
        run_cli("report", small, "--events", events, "--video", test_video, "-o", page),
        "the record's frames are 480x360",
    )
    assert not page.exists()
    done = run_cli("report", record)
    assert done.returncode == 0 and (tmp_path / "r_report.html").exists()


def _still_video(path: Path, picture: np.ndarray, frames: int = 30) -> Path:
    """A 25 fps video at `path` of `picture` (RGB) held for `frames` frames."""
    from app.sinks import VideoSink

    with VideoSink(path, (picture.shape[1], picture.shape[0]), 25.0, preset="medium") as sink:
        for _ in range(frames):
            sink.write(picture)
    return path


def _thumbnail(uri: str, flags: int = cv2.IMREAD_GRAYSCALE) -> np.ndarray:
    """The picture of a thumbnail's JPEG data URI (grey, or BGR with `cv2.IMREAD_COLOR`)."""
    data = np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8)
    return np.asarray(cv2.imdecode(data, flags))


def test_thumbnails_are_levelled_as_the_record_was(tmp_path: Path) -> None:
    """An event's thumbnail is the video's frame levelled by the turn the record says `process`
    levelled it by (its `roll_deg`, read off the footage), as with `--roll` stated: a level
    white bar of a picture turned 5 degrees comes out level; `--roll` overrides the record."""
    from app.report import event_thumbnails

    level = np.full((360, 640, 3), 60, np.uint8)
    level[170:190, 120:520] = 255
    turn = cv2.getRotationMatrix2D((319.5, 179.5), 5.0, 1.0)
    video = _still_video(tmp_path / "turned.mp4", cv2.warpAffine(level, turn, (640, 360)))
    event = Event("lane_departure", 10, 20, 0.4, 0.8)
    rows = _rows(30)
    read = [{**row, "roll_deg": 5.0} if row["frame"] >= 5 else row for row in rows]

    def bar_lean(uri: str) -> float:
        """The lean in degrees (rising to the right) of the thumbnail's white bar."""
        ys, xs = np.nonzero(_thumbnail(uri) > 200)
        return float(-np.degrees(np.arctan(np.polyfit(xs, ys, 1)[0])))

    assert abs(bar_lean(event_thumbnails(video, read, [event], None)[0])) < 0.5
    assert abs(bar_lean(event_thumbnails(video, rows, [event], None)[0]) - 5.0) < 0.5
    assert abs(bar_lean(event_thumbnails(video, read, [event], None, 0.0)[0]) - 5.0) < 0.5


def test_thumbnails_of_a_lens_known_by_its_focal_length_are_not_undistorted(
    tmp_path: Path,
) -> None:
    """Where the record says its distances followed a focal length (`focal_mm`: `process` was
    given `--focal-length`, and so left the shipped calibration out), an event's thumbnail is
    the frame as decoded, as `process` showed it; without it the frame is undistorted."""
    from app.report import event_thumbnails
    from camera_cal import default_calibration_path, load_calibration

    picture = np.full((360, 640, 3), 60, np.uint8)
    picture[20:30, 40:600] = 255  # near the top edge, where the shipped lens bends most
    video = _still_video(tmp_path / "phone.mp4", picture)
    event = Event("lane_departure", 10, 20, 0.4, 0.8)
    rows = _rows(30)
    stated = [{**row, "focal_mm": 30.0} for row in rows]
    shipped = load_calibration(default_calibration_path())

    decoded = _thumbnail(event_thumbnails(video, rows, [event], None)[0]).astype(np.float64)
    known = _thumbnail(event_thumbnails(video, stated, [event], shipped)[0])
    undistorted = _thumbnail(event_thumbnails(video, rows, [event], shipped)[0])
    assert np.abs(known - decoded).max() == 0
    assert np.abs(undistorted - decoded).mean() > 2


def test_thumbnails_of_a_video_processed_reduced(tmp_path: Path) -> None:
    """A video processed at a reduced size (4K at 1080p, `process --max-size`) has a record of
    the reduced frames: its thumbnails are of frames decoded at that size, with the record's
    box where it was; a record of another aspect ratio is still refused."""
    from app.report import event_thumbnails

    picture = np.full((360, 640, 3), 60, np.uint8)
    picture[200:260, 300:400] = 255  # the car, at (150, 100)-(200, 130) in the halved frames
    video = _still_video(tmp_path / "large.mp4", picture)
    event = Event("closing_fast", 10, 20, 0.4, 0.8, 1, 2.0)
    car = {"id": 1, "box": [150, 100, 200, 130], "score": 0.9}
    rows = [{**row, "size": [320, 180], "vehicles": [car]} for row in _rows(30)]
    (uri,) = event_thumbnails(video, rows, [event], None).values()
    thumb = _thumbnail(uri, cv2.IMREAD_COLOR)  # BGR: the box drawn red
    red = (thumb[..., 2] > 180) & (thumb[..., 1] < 120)
    ys, xs = np.nonzero(red)
    scale = thumb.shape[1] / 320
    assert abs(xs.min() / scale - 150) < 4 and abs(xs.max() / scale - 200) < 4
    assert abs(ys.min() / scale - 100) < 4 and abs(ys.max() / scale - 130) < 4
    other = [{**row, "size": [240, 180]} for row in rows]
    with pytest.raises(InputError, match="240x180"):
        event_thumbnails(video, other, [event], None)


def test_thumbnails_of_a_picture_turned_upright(tmp_path: Path) -> None:
    """A video `process --rotate 270` stood upright (stored on its side, as a phone's that lost
    its tag) has a record of the upright frames and says the turn (`rotate_deg`): its
    thumbnails are of the frames turned so, the record's box on the car; without the turn the
    record's size is not the video's, and it is refused."""
    from app.report import event_thumbnails

    upright = np.full((360, 640, 3), 60, np.uint8)
    upright[200:260, 300:400] = 255  # the car
    stored = np.ascontiguousarray(np.rot90(upright, -1))  # turned clockwise: 360x640 stored
    video = _still_video(tmp_path / "sideways.mp4", stored)
    event = Event("closing_fast", 10, 20, 0.4, 0.8, 1, 2.0)
    car = {"id": 1, "box": [300, 200, 400, 260], "score": 0.9}
    rows = [{**row, "rotate_deg": 270, "vehicles": [car]} for row in _rows(30)]
    (uri,) = event_thumbnails(video, rows, [event], None).values()
    thumb = _thumbnail(uri, cv2.IMREAD_COLOR)
    scale = thumb.shape[1] / 640
    assert abs(thumb.shape[0] / scale - 360) < 2
    white = (thumb.min(axis=2) > 200).nonzero()
    assert abs(white[1].mean() / scale - 350) < 4 and abs(white[0].mean() / scale - 230) < 4
    told_nothing = [{k: v for k, v in row.items() if k != "rotate_deg"} for row in rows]
    with pytest.raises(InputError, match="360x640"):
        event_thumbnails(video, told_nothing, [event], None)
