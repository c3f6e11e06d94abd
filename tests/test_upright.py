"""Which way up a picture is, read off its sky: upright clips of every camera vote for the top,
the same clips turned vote for the side their sky was turned to, and `process` says so."""

from __future__ import annotations

import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.drivers import SKY, SKY_START
from app.mounting import upright_note
from app.sources import ffmpeg_binary, probe_video, read_frames, within_size
from camera_cal.upright import SkyVote, frames_vote, sky_scores, sky_side, sky_vote
from tests.helpers import assert_one_line_error, read_record, run_cli

CONFIG = SKY


def _sampled(video: Path, limit: int = 500) -> list[np.ndarray]:
    """Every `CONFIG.every`-th of the first `limit` frames at 360 rows, as `--rotate auto` reads
    a video's start."""
    info = within_size(probe_video(video), SKY_START[1])
    frames = read_frames(video, info, 0, min(limit, info.n_frames))
    return [frame for k, frame in enumerate(frames) if k % CONFIG.every == 0]


def _vote(frames: list[np.ndarray], quarters: int) -> SkyVote:
    """The sky vote of `frames` turned `quarters` quarter turns clockwise."""
    return frames_vote([np.rot90(f, -quarters) for f in frames], CONFIG)


def _stored_anticlockwise(video: Path, clip: Path) -> None:
    """`video` re-encoded into `clip` turned a quarter anticlockwise (its sky on the left)."""
    command = [ffmpeg_binary(), "-loglevel", "error", "-i", str(video), "-vf",
               "transpose=cclock", "-c:v", "libx264", "-crf", "18", str(clip)]  # fmt: skip
    subprocess.run(command, check=True)


@pytest.mark.parametrize(
    "clip",
    [
        "videos/project_cut_1.mp4",
        "videos/project_cut_2.mp4",
        "wild/india_highway_wildfilms.mp4",
        "wild/la_freeway_minidashcam_2.mp4",
        "wild/night_highway_istock.mp4",
        "wild/rural_2lane_wet.mp4",
        "wild/udacity_challenge_video_clipA_2.4s.mp4",
        "wild/udacity_challenge_video_clipC_3.1s.mp4",
        "wild/us_highway_winter.mp4",
    ],
)
def test_the_sky_votes_for_the_side_a_clip_was_turned_to(
    request: pytest.FixtureRequest, clip: str
) -> None:
    """Upright, each clip's frames vote for the top (the snowy verge, the night, the wet road
    and the Indian haze too; clip A's dark skyline over a bright road outvotes the sky in a
    few of its frames, not in most). Turned a quarter turn clockwise, half a turn and a quarter
    anticlockwise, they vote for the right, the bottom and the left: the turn that stands them
    upright is 270, 180 and 90."""
    folder, name = clip.split("/")
    root = request.getfixturevalue("wild_dir" if folder == "wild" else "data_dir")
    video = root / name if folder == "wild" else root / clip
    frames = _sampled(video)
    upright = _vote(frames, 0)
    assert upright.side == 0 and upright.turn_deg == 0, upright
    for quarters, turn in ((1, 270), (2, 180), (3, 90)):
        vote = _vote(frames, quarters)
        assert vote.side == quarters and vote.turn_deg == turn, (quarters, vote)
        assert vote.votes[quarters] == upright.votes[0], (quarters, vote, upright)


def test_a_turned_still_permutes_the_side_scores(data_dir: Path) -> None:
    """Each side's strip spans the same share of the picture across it, so a quarter turn
    moves each side's score to the next side (within the sampling of every 4th pixel)."""
    still = cv2.cvtColor(
        cv2.imread(str(data_dir / "test_images" / "straight_lines1.jpg")), cv2.COLOR_BGR2RGB
    )
    h, w = still.shape[:2]
    scores = sky_scores(still, (0, 0, w, h))
    assert int(np.argmax(scores)) == 0
    for quarters in (1, 2, 3):
        turned = np.ascontiguousarray(np.rot90(still, -quarters))
        th, tw = turned.shape[:2]
        np.testing.assert_allclose(
            sky_scores(turned, (0, 0, tw, th)), np.roll(scores, quarters), atol=3
        )


def test_a_vote_needs_enough_frames_and_a_clear_majority() -> None:
    """Unsure frames do not vote; under `min_votes` votes or `least` of them for one side there
    is no verdict; a side's vote stands the picture upright by the turn that brings it up."""
    assert sky_vote([1] * 10).side == 1 and sky_vote([1] * 10).turn_deg == 270
    assert sky_vote([3] * 8 + [None] * 20 + [0] * 2).side == 3
    assert sky_vote([1] * 9 + [None] * 20).side is None  # too few votes
    assert sky_vote([0] * 7 + [2] * 3).side is None  # 70 %: split
    assert sky_vote([]).turn_deg is None
    assert sky_side(np.array([100.0, 80.0, 60.0, 50.0])) is None  # 20 ahead: unsure
    assert sky_side(np.array([40.0, 80.0, 120.0, 50.0])) == 2


def test_the_note_names_the_turn_that_stands_the_picture_upright() -> None:
    """The note adds the sky's turn to what the user passed, and says nothing of an upright
    picture or of a split vote."""
    right, bottom, left = (SkyVote((0, 12, 0, 0), 1), SkyVote((0, 0, 12, 0), 2),
                           SkyVote((0, 0, 0, 12), 3))  # fmt: skip
    said = upright_note(right, 0)
    assert said is not None and "on its right in 12 of 12" in said and "--rotate 270" in said
    told = upright_note(bottom, 90)
    assert told is not None and "after --rotate 90" in told and "pass --rotate 270" in told
    undo = upright_note(right, 90)
    assert undo is not None and "drop --rotate 90" in undo
    again = upright_note(bottom, 270)
    assert again is not None and "pass --rotate 90" in again
    dropped = upright_note(left, 270)
    assert dropped is not None and "drop --rotate 270" in dropped
    assert upright_note(SkyVote((12, 0, 0, 0), 0), 0) is None
    assert upright_note(SkyVote((6, 0, 6, 0), None), 0) is None


def test_process_says_a_clip_stored_turned_looks_turned_and_auto_turns_it(
    data_dir: Path, tmp_path: Path
) -> None:
    """project_cut_1 stored a quarter anticlockwise (its sky on the left): untold, `process`
    reads it as stored and notes that it looks turned and that --rotate 90 stands it upright;
    told --rotate 90 it says nothing of the sky. `--rotate auto` turns it 90 degrees, says so,
    and records what --rotate 90 records; the clip as it is, `--rotate auto`, is left as it is,
    and so is a clip too short to judge, with a note.
    A still is never turned by the sky (one frame can mislead), and a --rotate that is neither
    a number nor auto is refused in one line."""
    clip = tmp_path / "anticlockwise.mp4"
    video = data_dir / "videos" / "project_cut_1.mp4"
    _stored_anticlockwise(video, clip)
    record = tmp_path / "r.jsonl"
    common = ("--no-vehicles", "--calibration", "none", "--json", record, "-o", tmp_path / "o.mp4")
    untold = run_cli("process", clip, *common)
    assert untold.returncode == 0, untold.stderr
    said = untold.stdout + untold.stderr
    assert "looks stored turned" in said and "on its left" in said and "--rotate 90" in said
    assert {tuple(r["size"]) for r in read_record(record)} == {(720, 1280)}
    told = run_cli("process", clip, *common, "--rotate", "90")
    assert told.returncode == 0, told.stderr
    assert "looks stored turned" not in told.stdout + told.stderr
    told_rows = read_record(record)
    assert {(tuple(r["size"]), r["rotate_deg"]) for r in told_rows} == {((1280, 720), 90)}
    auto = run_cli("process", clip, *common, "--rotate", "auto")
    assert auto.returncode == 0, auto.stderr
    said = auto.stdout + auto.stderr
    assert "--rotate auto: its sky lies on its left" in said and "turned 90 degrees" in said
    assert "looks stored turned" not in said
    assert read_record(record) == told_rows
    level = run_cli("process", video, *common, "--rotate", "AUTO")
    assert level.returncode == 0, level.stderr
    assert "--rotate auto" not in level.stdout + level.stderr
    assert all("rotate_deg" not in r for r in read_record(record))
    short = run_cli("process", data_dir / "videos" / "test_video.mp4", *common, "--rotate", "auto")
    assert short.returncode == 0, short.stderr  # 38 frames: 8 votes, too few to judge
    assert "--rotate auto could not tell which way up" in short.stdout + short.stderr
    assert all("rotate_deg" not in r for r in read_record(record))
    still = data_dir / "test_images" / "test5.jpg"  # its sky outvoted by a white road
    image = run_cli("process", still, "--no-vehicles", "-o", tmp_path / "s.jpg", "--rotate", "auto")
    assert image.returncode == 0, image.stderr
    assert "one still can mislead: it is read as stored" in image.stdout + image.stderr
    bad = run_cli("process", video, "-o", tmp_path / "x.mp4", "--rotate", "sideways")
    assert_one_line_error(bad, "--rotate sideways", "or auto")
    assert not (tmp_path / "x.mp4").exists()


def test_no_reframing_of_a_clip_moves_its_sky(data_dir: Path) -> None:
    """project_cut_2 re-framed every way the re-framed table does (the horizon moved, crops,
    bars, sizes, mirrored, turned a few degrees, a phone held upright, dusk, a wider lens)
    votes for the top; without colour it may be unsure, never for another side."""
    from app.reframe import (
        MONOCHROME_FRAMING,
        UNTOLD_ROLL_FRAMINGS,
        WIDE_LENS_FRAMING,
        dusk_framings,
        reframe_image,
        standard_framings,
        upright_framing,
    )

    video = data_dir / "videos" / "project_cut_2.mp4"
    info = probe_video(video)
    frames = [f for k, f in enumerate(read_frames(video, info)) if k % CONFIG.every == 0]
    framings = (*standard_framings(info.size), upright_framing(info.size),
                *dusk_framings(info.size), *UNTOLD_ROLL_FRAMINGS, WIDE_LENS_FRAMING)  # fmt: skip
    for framing in framings:
        vote = frames_vote([reframe_image(f, framing) for f in frames], CONFIG)
        assert vote.side == 0, (framing.name, vote)
    grey = frames_vote([reframe_image(f, MONOCHROME_FRAMING) for f in frames], CONFIG)
    assert grey.side in (0, None) and sum(grey.votes[1:]) == 0, grey


def test_batch_turns_a_clip_stored_turned_with_rotate_auto(data_dir: Path, tmp_path: Path) -> None:
    """`batch --rotate auto` over a folder of project_cut_1 stored a quarter anticlockwise and
    as it is: the turned one is stood upright (its frames table says rotate_deg 90 and its
    manifest notes say why), the other is left as it is."""
    import pyarrow.parquet as pq

    folder = tmp_path / "in"
    folder.mkdir()
    video = data_dir / "videos" / "project_cut_1.mp4"
    _stored_anticlockwise(video, folder / "turned.mp4")
    (folder / "level.mp4").write_bytes(video.read_bytes())
    out = tmp_path / "out"
    result = run_cli("batch", folder, "--out", out, "--workers", "1", "--no-video",
                     "--rotate", "auto")  # fmt: skip
    assert result.returncode == 0, result.stderr
    frames = pq.read_table(out / "table" / "frames").to_pylist()
    turns = {(f["video"], f["rotate_deg"]) for f in frames}
    assert turns == {("turned.mp4", 90), ("level.mp4", 0)}, turns
    notes = {
        Path(r["path"]).name: r["notes"]
        for r in pq.read_table(out / "table" / "manifest.parquet").to_pylist()
    }
    assert "--rotate auto: its sky lies on its left" in notes["turned.mp4"]
    assert "--rotate auto" not in notes["level.mp4"]


def test_rotate_auto_votes_with_the_part_before(data_dir: Path, tmp_path: Path) -> None:
    """A drive's parts are turned alike: test_video stored turned is too short to judge alone
    (8 votes), but `--after` project_cut_1 stored turned alike, `--rotate auto` pools the two
    parts' votes and turns it 90 degrees, saying so."""
    first, second = tmp_path / "part1.mp4", tmp_path / "part2.mp4"
    _stored_anticlockwise(data_dir / "videos" / "project_cut_1.mp4", first)
    _stored_anticlockwise(data_dir / "videos" / "test_video.mp4", second)
    record = tmp_path / "r.jsonl"
    common = ("--no-vehicles", "--calibration", "none", "--json", record, "-o", tmp_path / "o.mp4")
    alone = run_cli("process", second, *common, "--rotate", "auto")
    assert alone.returncode == 0, alone.stderr
    assert "could not tell which way up" in alone.stdout + alone.stderr
    pooled = run_cli("process", second, *common, "--rotate", "auto", "--after", first)
    assert pooled.returncode == 0, pooled.stderr
    said = pooled.stdout + pooled.stderr
    assert "its sky lies on its left" in said and "part1.mp4's, the part before it" in said
    assert {(tuple(r["size"]), r["rotate_deg"]) for r in read_record(record)} == {((1280, 720), 90)}
