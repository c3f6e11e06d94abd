"""What the user says of how the camera is mounted, and the checks that it is a dashcam's.

Each value takes the place of what the footage or the tuned camera would give; the CLI builds
one `Mounting` from `--horizon`, `--camera-height`, `--traffic`, `--roll`, `--facing`,
`--focal-length`, `--dash-spacing` and `--rotate`, and the pipeline reads it (app/pipeline.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from app.errors import InputError
from app.sources import VideoInfo, reduced_row
from camera_cal import SIDES, US_DASH_SPACING_M, SkyVote


@dataclass(frozen=True)
class Mounting:
    """What the user says of how the camera is mounted, each in place of what the footage or
    the tuned camera would give: the horizon row (None: estimated from the footage), the height
    over the road in metres (None: a car's; sizes the vehicle windows), traffic keeping left
    (the vehicle stage sees every frame mirrored and its boxes come back mirrored,
    app/traffic.py), the picture's turn in degrees anticlockwise (levelled with the lens; None:
    read off the vehicles' rear edges or the lane lines' spacing, `camera_cal.level`, and
    levelled from then on) and which way the camera looks (`FACINGS`: "auto" reads it from the
    road's motion, `app.facts.Facing`; "rear" is a rear camera's file as its lens sees the
    road, its sides swapped, so the vehicle stage sees its frames mirrored; "rear-mirrored" one
    saved mirrored, as a rear-view mirror shows the road, its writing backwards and its sides
    as ahead), and
    the lens's focal length in 35 mm terms (None: the shipped camera's; sets the distances of a
    camera without a calibration, see `camera_cal.undistort.focal_scale_height`), and the
    spacing of the lane dashes on the roads it films, in metres, from which the road's length
    scale is read where the lens is not known (`camera_cal.DashScale`; None: not read),
    and the quarter turns, in degrees clockwise, that stand its picture upright as stored (a
    camera mounted upside down: 180; a phone's video that lost its rotation tag: 90 or 270):
    decoding turns the frames, and the calibration with them; or, `rotate_auto`, the turn the
    sky of a video's first seconds votes for (`app.drivers.sky_mounting`)."""

    horizon_y: float | None = None
    camera_height_m: float | None = None
    keep_left: bool = False
    roll_deg: float | None = None
    facing: str = "auto"
    focal_mm: float | None = None
    dash_spacing_m: float | None = US_DASH_SPACING_M
    rotate_deg: int = 0
    rotate_auto: bool = False

    @property
    def rear(self) -> bool | None:
        """Whether the user says the camera looks back (None: not said)."""
        return None if self.facing == "auto" else self.facing != "front"

    @property
    def mirrored(self) -> bool:
        """Whether the vehicle stage sees the frames mirrored: traffic keeping left seen ahead,
        or traffic keeping right seen behind (either, as traffic keeping right seen ahead)."""
        return self.keep_left != (self.facing == "rear")


# Which way a camera may look: read from the road's motion, ahead, back (the file as the lens
# sees the road), back saved mirrored (as a rear-view mirror shows it).
FACINGS = ("auto", "front", "rear", "rear-mirrored")


def check_facing(facing: str) -> None:
    """A user's facing must be one of `FACINGS`."""
    if facing not in FACINGS:
        raise InputError(
            f"--facing {facing} is not a way a camera looks; give {', '.join(FACINGS[:-1])} or "
            f"{FACINGS[-1]}"
        )


# Camera heights over the road a user may state, in metres (a car's bumper to a lorry's roof).
CAMERA_HEIGHTS_M = (0.3, 5.0)


def check_camera_height(height_m: float | None) -> None:
    """A user's camera height must be one a vehicle can have."""
    low, high = CAMERA_HEIGHTS_M
    if height_m is not None and not low <= height_m <= high:
        raise InputError(
            f"--camera-height {height_m:g} m is not a dashcam's height over the road; "
            f"pass metres from {low:g} to {high:g} (a car's is about 1.2, a lorry's 2-2.5)"
        )


def camera_height_note(
    ground_scale: float, tuned_height_m: float, lane_width_m: float
) -> str | None:
    """What a user not stating the camera's height should hear where the lanes' learned
    `ground_scale` moved: they read as `lane_width_m` lanes seen from another height than the
    tuned camera's `tuned_height_m`, or as other lanes from that height. The vehicle windows
    stay sized for the tuned height (the road cannot tell the two apart; a car's size depends
    on the height alone), so the note gives the height the lanes imply and how to state it."""
    if ground_scale == 1.0 or ground_scale <= 0:
        return None
    implied = tuned_height_m / ground_scale
    return (
        f"its lanes read as {lane_width_m:g} m lanes seen from {implied:.1f} m over the road, or "
        f"as {'narrower' if ground_scale < 1 else 'wider'} lanes seen from {tuned_height_m:.2f} m "
        f"(the tuned camera's height, for which the vehicle windows are sized); if the camera is "
        f"mounted {'higher' if ground_scale < 1 else 'lower'}, pass --camera-height "
        f"{implied:.1f} (or its measured height) so they fit its vehicles"
    )


def aim_note(column_share: float | None, least: float = 0.04) -> str | None:
    """What a user should hear where the road's vanishing point lies well off the picture's
    middle over the footage (`column_share`: the median of its column's distance from the live
    picture's middle, over the live width; positive right): the camera looks to the road's
    other side, or the picture is cut off-centre. The lanes and the vehicles' sides are read
    along the road either way, but the side it lies towards is seen less far. None within
    `least` of the middle (a bend ahead moves it by a few per cent) or where it was not found."""
    if column_share is None or abs(column_share) <= least:
        return None
    side, looks = ("left", "right") if column_share < 0 else ("right", "left")
    return (
        f"its road runs towards a point {abs(column_share):.0%} of the width {side} of the "
        f"picture's middle: the camera looks {looks} of the road (or the picture is cut "
        f"off-centre); lanes and the vehicles' sides are read along the road, but less of its "
        f"{side} side is seen: aim the camera along the road to see both sides alike"
    )


def dash_note(
    length_scale: float, read_m: float | None, implausible_m: float | None, spacing_m: float
) -> str | None:
    """What a user should hear where the lane dashes, `spacing_m` apart on the road, moved the
    road's `length_scale` (the view read them `read_m` apart), or read `implausible_m` apart, too
    far from it for any lens: the distances and speed then assume the shipped camera's lens.
    None where the scale stayed 1 and the dashes agreed with it (or were not read)."""
    painted = f"{spacing_m:g} m apart" + (
        " (as on US highways; --dash-spacing M for other roads')"
        if spacing_m == US_DASH_SPACING_M
        else " (--dash-spacing)"
    )
    if implausible_m is not None:
        return (
            f"its lane dashes read {implausible_m:.1f} m apart, too far from {painted} for any "
            "lens, so its distances and speed assume the shipped camera's lens (--focal-length MM "
            "states its own)"
        )
    if length_scale == 1.0 or read_m is None:
        return None
    return (
        f"its lane dashes read {read_m:.1f} m apart where they are painted {painted}, so its "
        f"lens is taken as {max(length_scale, 1 / length_scale):.2f} times "
        f"{'wider' if length_scale < 1 else 'narrower'} than assumed: its distances and speed "
        f"are scaled by {length_scale:.2f} from the frame they were read on (--dash-spacing none "
        "keeps the assumed lens; --focal-length MM states its own)"
    )


# How far a user may say the picture is turned, in degrees: a dashcam mounted askew, not one
# on its side (a phone held upright is turned by its rotation tag).
MAX_ROLL_DEG = 30.0


def check_roll(roll_deg: float | None) -> None:
    """A user's roll must be a tilt a mounted dashcam can have (None: not stated)."""
    if roll_deg is not None and not abs(roll_deg) <= MAX_ROLL_DEG:
        raise InputError(
            f"--roll {roll_deg:g} is not a dashcam's tilt; pass degrees from "
            f"{-MAX_ROLL_DEG:g} to {MAX_ROLL_DEG:g} (positive: the picture turned anticlockwise, "
            "its horizon rising to the right)"
        )


# The turns, clockwise, that stand a picture upright: the quarter turns.
ROTATIONS = (0, 90, 180, 270)


def check_rotate(rotate_deg: int) -> None:
    """A user's rotation must be a quarter turn (a tilt is `--roll`'s)."""
    if rotate_deg not in ROTATIONS:
        raise InputError(
            f"--rotate {rotate_deg} is not a quarter turn; pass 90, 180 or 270 (degrees "
            "clockwise that stand the picture upright; a camera's tilt is --roll's)"
        )


def sky_where(side: int) -> str:
    """Where on the picture side `side` (index into `SIDES`) is, in a note's words."""
    return f"{'at' if side == 2 else 'on'} its {SIDES[side]}"


def upright_note(vote: SkyVote, told_deg: int) -> str | None:
    """What a user should hear where the frames' sky lies on another side than the top
    (`vote`, taken on the picture after the `told_deg` turn): the picture looks stored turned,
    and the turn that stands it upright. Told, acted on only where the user asks (`--rotate
    auto`): a dark skyline over a bright road outvotes the sky in a few clips' frames (README,
    Which way up). None where the sky
    voted for the top or did not hold the vote."""
    side, turn = vote.side, vote.turn_deg
    if side is None or turn is None or side == 0:
        return None
    total = (told_deg + turn) % 360
    advice = f"pass --rotate {total}" if total else f"drop --rotate {told_deg}"
    turned = f" after --rotate {told_deg}" if told_deg else ""
    where = sky_where(side)
    return (
        f"it looks stored turned{turned}: its sky (the brightest, bluest side) lies {where} in "
        f"{vote.votes[side]} of {sum(vote.votes)} frames sampled; if so, {advice} to stand it "
        "upright (the lanes, vehicles and facts are read as if its top were up)"
    )


# 35 mm-equivalent focal lengths a user may state, in mm: a fisheye's to a telephoto's (a
# phone's main camera is 24-28, the shipped dashcam's 31).
FOCAL_LENGTHS_MM = (8.0, 300.0)


def check_focal_length(focal_mm: float | None) -> None:
    """A user's focal length must be one a camera's lens can have."""
    low, high = FOCAL_LENGTHS_MM
    if focal_mm is not None and not low <= focal_mm <= high:
        raise InputError(
            f"--focal-length {focal_mm:g} mm is not a camera lens's; pass its 35 mm-equivalent "
            f"focal length, from {low:g} to {high:g} mm (a phone's main camera is about 26)"
        )


# Lane dash spacings a user may state, one dash and one gap, in metres (the UK's motorways 9,
# US highways 12.19, German autobahns 18, Japan's expressways 20).
DASH_SPACINGS_M = (3.0, 60.0)


def check_dash_spacing(spacing_m: float | None) -> None:
    """A user's dash spacing must be one a road's paint can have (None: not read)."""
    low, high = DASH_SPACINGS_M
    if spacing_m is not None and not low <= spacing_m <= high:
        raise InputError(
            f"--dash-spacing {spacing_m:g} m is not a lane's dash spacing; pass the metres from "
            f"one dash's start to the next one's, from {low:g} to {high:g} (US highways 12.19), "
            "or none"
        )


def check_horizon(horizon_y: float | None, size: tuple[int, int]) -> None:
    """A user's horizon row must lie inside the frame."""
    if horizon_y is not None and not 0 <= horizon_y < size[1]:
        raise InputError(
            f"--horizon {horizon_y:g} is outside the frame ({size[1]} rows); "
            f"pass a row from 0 to {size[1] - 1}"
        )


def check_mounting(mounting: Mounting, size: tuple[int, int] | None = None) -> None:
    """A user's mounting must be one a dashcam can have, and its horizon a row of frames of
    `size` (not checked without one)."""
    if size is not None:
        check_horizon(mounting.horizon_y, size)
    check_camera_height(mounting.camera_height_m)
    check_roll(mounting.roll_deg)
    check_facing(mounting.facing)
    check_focal_length(mounting.focal_mm)
    check_dash_spacing(mounting.dash_spacing_m)
    check_rotate(mounting.rotate_deg)


def video_mounting(mounting: Mounting, info: VideoInfo) -> Mounting:
    """A user's mounting checked against a video, its horizon (a row of the video as stored)
    as a row of the frames processed (`within_size` may have reduced them)."""
    check_mounting(mounting, info.reduced_from or info.size)
    return replace(mounting, horizon_y=reduced_row(mounting.horizon_y, info))
