"""Every parameter of the lane finder, as fractions of the frame where they depend on its size."""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class LaneConfig:
    """Lane finder settings; defaults fit the shared dashcam at any resolution of its aspect."""

    # Source trapezoid on the undistorted frame (fractions of width/height), measured on
    # straight_lines1/2: the ego lane's lines pass through these points.
    src_top_y: float = 0.635
    src_bottom_y: float = 0.95
    src_top_left_x: float = 0.4586
    src_top_right_x: float = 0.5438
    src_bottom_left_x: float = 0.2047
    src_bottom_right_x: float = 0.8203
    # Bird's-eye image: size as fractions of the frame, lane lines mapped to these columns.
    warp_width: float = 0.4
    warp_height: float = 0.3
    # ... of a frame at most this tall: a larger picture gives the view no finer paint in metres
    # worth its cost (2.3 times the pixels at 1080p), so it is sized as for 720 rows.
    max_warp_frame_height: float = 720.0
    dst_left_x: float = 0.3
    dst_right_x: float = 0.7
    # World scale: a US lane is 3.7 m wide; dashes are 3 m long (sets metres per warped row).
    lane_width_m: float = 3.7
    warp_length_m: float = 27.0  # road length covered by the trapezoid, from the 3 m dashes
    # Thresholds on the bird's-eye image (LAB channels, 0..255).
    line_width_m: float = 0.15
    white_tophat: float = 18.0
    white_min_l: float = 120.0
    # ... or, on a darker road, this much lighter than the road's median (the tuned camera's
    # asphalt reads about 80): at dusk paint is much lighter than the road but not as light (the
    # shared clips darkened to a road of 19 show their paint at 60-95, and no lane was found).
    white_above_road: float = 40.0
    # ... in full on a road this light or lighter (the tuned asphalt), in proportion on a darker
    # one: at dusk on concrete (road 62-66) the white dashes read 100-109, under road + 40, and
    # the lane was drawn from the yellow line and a made-up side 30-80 px off (0: always in full).
    white_margin_road: float = 80.0
    # ... and never below this, under which noise passes for paint: a dusk road's white line
    # reads 66-75 over a road of 2-11 (the wet rural road dimmed), and the shared clips at 0.25
    # of their light show their paint at 60-65; at 90 neither had a lane (see README).
    white_min_l_dark: float = 60.0
    yellow_tophat: float = 7.0
    yellow_min_b: float = 140.0
    min_paint_m: float = 0.5  # paint is kept where it runs along the road at least this far
    # Search.
    windows: int = 9
    window_margin_m: float = 0.55
    prior_margin_m: float = 0.45
    # Paint needed (m^2 of road; a 15 cm line gives 0.15 m^2 per metre): to re-centre a window,
    # and to fit a line at all.
    min_window_paint_m2: float = 0.026
    min_line_paint_m2: float = 0.13
    # Weak pulls towards the last frames (relative to each side's pixels weighing 1 in total):
    heading_prior: float = 0.01  # the lane centre's direction at the bottom row
    near_width_prior: float = 0.2  # the lane width at the bottom row, in pixels
    outlier_m: float = 0.25  # pixels farther than this from a first fit are dropped, then refit
    # History and sanity checks (frame counts at `frame_rate`; `at_rate` keeps their time).
    history: int = 3
    max_misses: int = 6
    motion_smoothing: int = 15  # frames of road advance averaged for the speed
    frame_rate: float = 25.0
    min_lane_width_m: float = 2.6
    max_lane_width_m: float = 5.6
    max_width_change_m: float = 1.8  # top vs bottom width: near parallel (pitch changes it)
    max_jump_m: float = 0.5  # x change of a line vs its smoothed fit: continuity
    min_radius_m: float = 50.0  # a lane bending tighter than this is not believed
    # ... nor, at our speed v, one tighter than v^2 / this: the sideways acceleration in m/s^2 of
    # taking the bend. Roads are built for about 2 at their design speed (superelevation and side
    # friction, ~0.2 g); a fit bending more (a wide lens's lines bowed, a dash seen askew) is
    # refitted at the tightest bend believed: the LA clip read 150-290 m at 100-120 km/h on a
    # straight freeway (up to 5.7 m/s^2), the shared clips' bends 2 at most.
    max_sideways_mps2: float = 3.0
    # ... nor one running off more than this from straight ahead at the car: a lane change
    # turns the car by 2-5 degrees, at 8 it would cross a lane in 26 m; the lines a car crosses
    # at a junction (zebra stripes, kerbs of a side road) run off at 10-20 degrees.
    max_heading_deg: float = 8.0
    # ... nor one the camera is outside of (|offset| over the width): that is a neighbouring
    # lane, a shoulder, or the lane left behind in a lane change; the lines are searched afresh
    # near the car.
    max_offset_share: float = 0.5
    # ... nor one whose inside (`inside_margin_m` in from its lines, and twice that off a line
    # along it) is painted over more than this share: a lane's holds no paint but an arrow's or
    # a seam's (at most 2.6 % in the shared clips, 0.9 % in the other cameras' but India's),
    # while India's pedestrian crossings paint 4.1-15.6 % of the lanes drawn across them.
    inside_margin_m: float = 0.3
    max_inside_paint: float = 0.04
    # ... nor any lane while a pedestrian crossing is in view: bars as wide as the first two of
    # `crossing_bar_m` and at least its third long (metres), `crossing_contrast` lighter than
    # the road beside them (a top-hat twice the widest bar wide), at least `crossing_bars` of
    # them side by side with gaps of `crossing_gap_m`, in rows over `crossing_min_m` of road or
    # more. A lane line is too thin for a bar, a car or a lit patch too wide and alone; over
    # the bars the lines' fits bend along their ends. The contrast is a paint's: from 18 grey
    # levels the project video's light concrete bridge (test1.jpg) read as bars over 1.9 m
    # (README, No lane over a pedestrian crossing).
    crossing_bar_m: tuple[float, float, float] = (0.25, 1.2, 1.0)
    crossing_gap_m: tuple[float, float] = (0.2, 1.5)
    crossing_bars: int = 4
    crossing_min_m: float = 1.0
    crossing_contrast: float = 30.0
    # A width sample for the ground scale needs the lines near parallel (widths within this
    # share: a horizon a few rows off, as in the first seconds, tilts them),
    # and counts as two lanes where paint runs along the middle in this share of the rows (a
    # dashed line paints 25-40 %).
    sample_parallel: float = 0.35
    middle_line_rows: float = 0.2
    # A line inside the lane drawn (one of its sides made up at the standard width, or its lines
    # further apart than this) bounds ours where the camera is this far or further from it; on
    # the line the car is astride, and the carriageway between the outer lines is where it is,
    # unless one of them was made up (then there is none: the made-up side cannot say which).
    one_lane_max_m: float = 4.6
    astride_m: float = 0.9
    # A lane no wider than `one_lane_max_m` holds no line along its middle: paint there in this
    # share of the rows (a solid line; a dashed one paints 25-40 %, project_cut_2's tar seam
    # 20-25 %) means one of its sides is a kerb or fence beyond an edge line (India's town).
    solid_line_rows: float = 0.5
    # A dashed line's dashes (lanes/dashes.py): paint in this share of the rows along it (a
    # solid line paints more, 0.6-1), read within this many metres of it, runs nearer than
    # `dash_bridge_m` joined (a dash the mask broke), dashes this long (metres) counted, and
    # followed while their near end is in the view's rows from this share of its height down.
    dash_share: tuple[float, float] = (0.1, 0.6)
    dash_half_width_m: float = 0.3
    dash_bridge_m: float = 1.5
    dash_length_m: tuple[float, float] = (1.5, 7.0)
    dash_near: float = 0.45
    straight_radius_m: float = 10_000.0  # larger radii are reported as straight (inf)
    polyline_points: int = 24

    def at_rate(self, fps: float) -> LaneConfig:
        """The same settings for video at `fps` frames a second: the lines' history, the misses
        they survive and the advances averaged cover the same time (at least a frame)."""
        if fps <= 0 or fps == self.frame_rate:
            return self

        def frames(count: int) -> int:
            return max(1, round(count * fps / self.frame_rate))

        return replace(
            self,
            history=frames(self.history),
            max_misses=frames(self.max_misses),
            motion_smoothing=frames(self.motion_smoothing),
            frame_rate=fps,
        )
