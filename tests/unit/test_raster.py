"""The NumPy rasteriser: palette and quantisation, cameras, dots, lines, text, ground."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.export import raster as R
from animsim.export.raster import (
    BACKGROUND_RGB,
    FONT,
    GROUND_EDGE_RGB,
    GROUND_RGB,
    PALETTE,
    Canvas,
    OrthoCamera,
    PerspectiveCamera,
    bounds_from_positions,
    make_camera,
    paint_planes,
    parse_size,
    quantise,
)
from animsim.export.raster import canvas as raster_canvas

BOX = (np.zeros(3), np.full(3, 4.0))  # a 4 m cube from the origin
SIZE = (100, 100)  # 25 px per metre for BOX in the orthographic views
RED = (1.0, 0.0, 0.0, 1.0)
BLUE = (0.0, 0.0, 1.0, 1.0)


def nearest_palette(rgb: np.ndarray) -> np.ndarray:
    """Brute-force nearest palette index of (..., 3) byte colours."""
    d = ((rgb[..., None, :].astype(np.float64) - PALETTE.astype(np.float64)) ** 2).sum(-1)
    return d.argmin(-1)


def pixel_rgb(canvas: Canvas, x: int, y: int) -> np.ndarray:
    return canvas.rgb[y, x].astype(np.float64)


# -- palette and quantisation ------------------------------------------------


def test_palette_is_256_distinct_colours_with_cube_and_greys():
    assert PALETTE.shape == (256, 3) and PALETTE.dtype == np.uint8
    assert len(np.unique(PALETTE, axis=0)) == 256
    assert tuple(PALETTE[0]) == (0, 0, 0) and tuple(PALETTE[215]) == (255, 255, 255)
    greys = PALETTE[216:]
    assert (greys[:, 0] == greys[:, 1]).all() and (greys[:, 1] == greys[:, 2]).all()


def test_lut_is_the_nearest_palette_colour_of_each_cell():
    rng = np.random.default_rng(1)
    cells = rng.integers(0, R.LUT_LEVELS, size=(4000, 3))
    index = cells[:, 0] | (cells[:, 1] << R.LUT_BITS) | (cells[:, 2] << (2 * R.LUT_BITS))
    rgb = cells * (255.0 / R.LUT_MAX)
    d = ((rgb[:, None, :] - PALETTE[None].astype(np.float64)) ** 2).sum(-1)
    got = d[np.arange(len(d)), R.palette_lut()[index]]
    np.testing.assert_allclose(got, d.min(axis=1))


def test_quantise_maps_each_pixel_to_its_nearest_palette_colour():
    rng = np.random.default_rng(2)
    image = rng.random((30, 40, 3)).astype(np.float32)
    levels = np.rint(image * R.LUT_MAX) / R.LUT_MAX * 255.0
    expected_d = ((levels[..., None, :] - PALETTE.astype(np.float64)) ** 2).sum(-1)
    got = quantise(image)
    assert got.shape == (30, 40) and got.dtype == np.uint8
    chosen = np.take_along_axis(expected_d, got[..., None].astype(np.int64), -1)[..., 0]
    np.testing.assert_allclose(chosen, expected_d.min(-1))


def test_quantise_is_deterministic_and_canvas_equals_array():
    rng = np.random.default_rng(3)
    canvas = Canvas(37, 23)
    canvas.draw_dots(rng.uniform(0, 37, (40, 2)), rng.uniform(1, 5, 40), rng.random((40, 4)))
    a = quantise(canvas)
    b = quantise(canvas)
    c = quantise(np.array(canvas.rgb))
    assert a.tobytes() == b.tobytes() == c.tobytes()


def test_quantise_clips_out_of_range_arrays():
    image = np.array([[[2.0, -1.0, 0.5]]], dtype=np.float32)
    assert quantise(image)[0, 0] == quantise(np.array([[[1.0, 0.0, 0.5]]], dtype=np.float32))[0, 0]


@pytest.mark.parametrize(
    "colour",
    [R.BACKGROUND_RGB, R.GROUND_RGB, R.GROUND_ALT_RGB, R.GROUND_EDGE_RGB, R.SPRING_RGB, R.TEXT_RGB],
)
def test_named_colours_quantise_to_themselves(colour):
    canvas = Canvas(2, 2, background=colour)
    index = quantise(canvas)[0, 0]
    assert tuple(PALETTE[index]) == tuple(round(c * 255) for c in colour)


def test_to_rgb8_rounds():
    image = np.array([[[0.0, 0.5, 1.0]]], dtype=np.float32)
    assert R.to_rgb8(image).tolist() == [[[0, 128, 255]]]


# -- sizes and bounds ----------------------------------------------------------


def test_parse_size():
    assert parse_size("480x320") == (480, 320)
    assert parse_size((16, 9)) == (16, 9)
    for bad in ("0x10", "10x0", "abc", "10x", "-5x5", "10x10x10", (0, 10), (10.5, 3)):
        with pytest.raises(ValueError):
            parse_size(bad)


def test_bounds_from_positions_adds_margin_and_accepts_iterables():
    frames = [np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5]]), np.array([[3.0, -1.0, 0.0]])]
    lo, hi = bounds_from_positions(iter(frames), margin=0.1)  # a generator, read once
    pad = 0.1 * 3.0  # 10 % of the largest extent (x: 0..3)
    np.testing.assert_allclose(lo, [0 - pad, -1 - pad, 0 - pad])
    np.testing.assert_allclose(hi, [3 + pad, 2 + pad, 0.5 + pad])
    lo2, hi2 = bounds_from_positions(np.stack([np.pad(frames[0], ((0, 0), (0, 0)))]), margin=0)
    np.testing.assert_allclose(lo2, [0, 0, 0])
    np.testing.assert_allclose(hi2, [1, 2, 0.5])


def test_bounds_ignore_nan_and_give_a_box_to_a_still_point():
    lo, hi = bounds_from_positions(np.array([[1.0, 2.0, 3.0], [np.nan, 9.0, np.inf]]))
    np.testing.assert_allclose(hi - lo, np.full(3, R.DEFAULT_EXTENT))
    np.testing.assert_allclose((lo + hi) / 2, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError):
        bounds_from_positions(np.zeros((4, 2)))


# -- cameras -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("view", "point", "pixel", "depth"),
    [
        ("xy", (1.0, 3.0, 2.0), (25.0, 25.0), -2.0),
        ("xy", (4.0, 0.0, 0.0), (100.0, 100.0), 0.0),
        ("xz", (1.0, 2.0, 3.0), (25.0, 25.0), -2.0),
        ("xz", (2.0, 0.0, 0.0), (50.0, 100.0), 0.0),
        ("yz", (2.0, 1.0, 3.0), (25.0, 25.0), -2.0),
        ("yz", (0.0, 4.0, 4.0), (100.0, 0.0), 0.0),
        ("zy", (1.0, 1.0, 3.0), (75.0, 75.0), -1.0),  # z across, y up
        ("zy", (2.0, 4.0, 0.0), (0.0, 0.0), -2.0),
    ],
)
def test_orthographic_views_map_known_points(view, point, pixel, depth):
    camera = make_camera(view, BOX, SIZE)
    proj = camera.project(np.array([point, (2.0, 2.0, 2.0)]))
    np.testing.assert_allclose(proj.pixel[0], pixel)
    np.testing.assert_allclose(proj.pixel[1], (50.0, 50.0))  # the centre
    assert proj.depth[0] == pytest.approx(depth)
    np.testing.assert_allclose(proj.px_per_m, 25.0)
    assert proj.visible.all()


def test_orthographic_keeps_aspect_and_centres_the_bounds():
    camera = OrthoCamera("xy", (np.array([0.0, 0.0, 0.0]), np.array([8.0, 2.0, 0.0])), (100, 100))
    assert camera.scale == pytest.approx(12.5)  # x decides: 100 px / 8 m
    proj = camera.project(np.array([[0.0, 1.0, 0.0], [8.0, 2.0, 0.0]]))
    np.testing.assert_allclose(proj.pixel, [[0.0, 50.0], [100.0, 37.5]])


def test_nonfinite_points_are_not_visible():
    proj = make_camera("xy", BOX, SIZE).project(np.array([[np.nan, 0.0, 0.0], [1.0, 1.0, 1.0]]))
    assert proj.visible.tolist() == [False, True]


def test_perspective_front_view_maps_known_points():
    camera = PerspectiveCamera(BOX, (200, 100), azimuth=0.0, elevation=0.0, distance=10.0, fov=60.0)
    focal = 50 / np.tan(np.radians(30))  # half the smaller side over tan(fov/2)
    centre = np.array([2.0, 2.0, 2.0])
    steps = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -5.0]])
    proj = camera.project(centre + steps)
    np.testing.assert_allclose(proj.pixel[0], (100.0, 50.0))
    np.testing.assert_allclose(proj.pixel[1], (100.0 + focal / 10, 50.0))  # x is right
    np.testing.assert_allclose(proj.pixel[2], (100.0, 50.0 - focal / 10))  # y is up
    np.testing.assert_allclose(proj.depth, [10.0, 10.0, 10.0, 15.0])  # -z is away
    np.testing.assert_allclose(proj.px_per_m[0], focal / 10)


def test_perspective_azimuth_turns_around_the_up_axis():
    camera = PerspectiveCamera(BOX, SIZE, azimuth=90.0, elevation=0.0, distance=10.0)
    np.testing.assert_allclose(camera.eye, [12.0, 2.0, 2.0])  # on +x
    proj = camera.project(np.array([[2.0, 2.0, 1.0]]))  # -z is to the right seen from +x
    assert proj.pixel[0, 0] > 50.0
    assert proj.pixel[0, 1] == pytest.approx(50.0)


def test_perspective_auto_distance_frames_the_whole_box():
    corners = np.array([[x, y, z] for x in (0, 4) for y in (0, 4) for z in (0, 4)], dtype=float)
    for azimuth, elevation in ((30, 20), (-120, 60), (0, 90), (45, -90)):
        camera = PerspectiveCamera(BOX, (120, 80), azimuth=azimuth, elevation=elevation)
        proj = camera.project(corners)
        assert proj.visible.all()
        assert (proj.pixel >= 0).all() and (proj.pixel[:, 0] <= 120).all() and (proj.pixel[:, 1] <= 80).all()


def test_perspective_hides_points_behind_the_camera():
    camera = PerspectiveCamera(BOX, SIZE, azimuth=0.0, elevation=0.0, distance=10.0)
    proj = camera.project(np.array([[2.0, 2.0, 20.0], [2.0, 2.0, 2.0]]))
    assert proj.visible.tolist() == [False, True]


def test_camera_parameters_are_checked():
    with pytest.raises(ValueError):
        make_camera("top", BOX, SIZE)
    with pytest.raises(ValueError):
        make_camera("3d", BOX, SIZE, elevation=91.0)
    with pytest.raises(ValueError):
        make_camera("3d", BOX, SIZE, distance=-1.0)
    with pytest.raises(ValueError):
        make_camera("xy", (np.ones(3), np.zeros(3)), SIZE)  # hi < lo
    with pytest.raises(ValueError):
        make_camera("xy", BOX, (0, 10))


# -- dots --------------------------------------------------------------------


def test_dot_appears_at_its_pixel_with_its_colour():
    canvas = Canvas(40, 30)
    canvas.draw_dots(np.array([[10.5, 20.5]]), 3.0, RED)  # the centre of pixel (10, 20)
    np.testing.assert_allclose(pixel_rgb(canvas, 10, 20), RED[:3])
    np.testing.assert_allclose(pixel_rgb(canvas, 12, 21), RED[:3])  # inside the disc
    np.testing.assert_allclose(pixel_rgb(canvas, 15, 20), BACKGROUND_RGB, atol=1e-6)  # 4.5 px away
    rim = pixel_rgb(canvas, 13, 21)  # distance sqrt(10) = 3.16: coverage 0.34
    cover = 3.5 - np.sqrt(10)
    np.testing.assert_allclose(
        rim, np.array(BACKGROUND_RGB) * (1 - cover) + np.array(RED[:3]) * cover, atol=1e-6
    )
    # Only pixels within r + 0.5 of the centre are touched.
    ys, xs = np.nonzero((canvas.rgb != np.float32(BACKGROUND_RGB[0])).any(axis=2))
    assert (np.hypot(xs + 0.5 - 10.5, ys + 0.5 - 20.5) < 3.5).all()
    assert tuple(PALETTE[quantise(canvas)[20, 10]]) == (255, 0, 0)


def test_dot_alpha_blends_with_the_background():
    canvas = Canvas(20, 20)
    canvas.draw_dots(np.array([[5.5, 5.5]]), 2.0, (1.0, 1.0, 1.0, 0.5))
    expected = 0.5 * np.array(BACKGROUND_RGB) + 0.5
    np.testing.assert_allclose(pixel_rgb(canvas, 5, 5), expected, atol=1e-6)


def test_later_dots_are_on_top():
    canvas = Canvas(20, 20)
    canvas.draw_dots(np.array([[5.5, 5.5], [5.5, 5.5]]), [3.0, 2.0], np.array([RED, BLUE]))
    np.testing.assert_allclose(pixel_rgb(canvas, 5, 5), BLUE[:3], atol=1e-6)
    # 2 px from the centre: the red disc covers it, the blue one's rim half covers it.
    np.testing.assert_allclose(pixel_rgb(canvas, 7, 5), (0.5, 0.0, 0.5), atol=1e-6)


def test_composite_equals_sequential_over():
    rng = np.random.default_rng(4)
    canvas = Canvas(6, 5)
    canvas.rgb[...] = rng.random((5, 6, 3))
    expected = canvas.rgb.astype(np.float64).reshape(-1, 3)
    n = 200  # about 7 fragments per pixel
    pixel = rng.integers(0, 30, n)
    alpha = rng.random(n).astype(np.float32)
    alpha[::7] = 1.0  # some opaque ones
    order = rng.permutation(n)
    colour = rng.random((n, 3)).astype(np.float32)  # fragment k has colour[order[k]]
    canvas.composite(pixel, alpha, colour, order)
    for k in np.argsort(order):  # the plain loop, back to front
        c = colour[order[k]]
        expected[pixel[k]] = expected[pixel[k]] * (1 - alpha[k]) + c * alpha[k]
    np.testing.assert_allclose(canvas.rgb.reshape(-1, 3), expected, atol=1e-5)


def test_dots_partly_outside_or_invalid_are_handled():
    canvas = Canvas(10, 10)
    canvas.draw_dots(
        np.array([[0.0, 0.0], [np.nan, 1.0], [50.0, 50.0], [9.9, 5.0]]),
        np.array([3.0, 3.0, 3.0, np.inf]),
        RED,
    )
    np.testing.assert_allclose(pixel_rgb(canvas, 0, 0), RED[:3])
    np.testing.assert_allclose(pixel_rgb(canvas, 9, 5), BACKGROUND_RGB, atol=1e-6)  # inf radius: skipped


def test_tiny_dots_stay_visible():
    canvas = Canvas(10, 10)
    canvas.draw_dots(np.array([[4.5, 4.5]]), 0.01, RED)
    assert pixel_rgb(canvas, 4, 4)[0] > 0.9


# -- lines -------------------------------------------------------------------


def painted(canvas: Canvas) -> np.ndarray:
    return (np.abs(canvas.rgb - np.float32(BACKGROUND_RGB)) > 1e-6).any(axis=2)


def test_horizontal_line_covers_exactly_its_pixels():
    canvas = Canvas(30, 10)
    canvas.draw_lines(np.array([[2.5, 5.5]]), np.array([[20.5, 5.5]]), (1.0, 0.0, 0.0))
    expected = np.zeros((10, 30), dtype=bool)
    expected[5, 2:21] = True
    assert (painted(canvas) == expected).all()
    np.testing.assert_allclose(pixel_rgb(canvas, 11, 5), (1.0, 0.0, 0.0))


def test_diagonal_line_is_connected_between_its_endpoints():
    canvas = Canvas(40, 40)
    canvas.draw_lines(np.array([[3.2, 4.7], [30.0, 2.0]]), np.array([[35.9, 20.1], [31.0, 38.0]]))
    mask = painted(canvas)
    assert mask[4, 3] and mask[20, 35] and mask[2, 30] and mask[37, 30]
    for x in range(3, 36):  # x-major line: one pixel in every column
        assert mask[:, x].any()
    np.testing.assert_allclose(pixel_rgb(canvas, 3, 4), R.SPRING_RGB)


def test_lines_are_clipped_and_bad_lines_skipped():
    canvas = Canvas(20, 20)
    canvas.draw_lines(
        np.array([[-1e6, 10.5], [-5.0, -5.0], [np.nan, 1.0]]),
        np.array([[1e6, 10.5], [-1.0, 30.0], [5.0, 5.0]]),
        np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
    )
    mask = painted(canvas)
    assert mask[10].all() and mask.sum() == 20  # the long line, clipped; the others unseen
    np.testing.assert_allclose(pixel_rgb(canvas, 7, 10), (0.0, 1.0, 0.0))


# -- text --------------------------------------------------------------------


def test_font_has_every_character_of_a_time_stamp():
    for ch in "0123456789.st= ":
        assert ch in FONT and FONT[ch].shape[0] == R.GLYPH_HEIGHT
    digits = [FONT[d].tobytes() for d in "0123456789"]
    assert len(set(digits)) == 10


def test_draw_text_stamps_the_glyphs():
    canvas = Canvas(20, 12)
    canvas.draw_text(2, 1, "1", rgb=(1.0, 1.0, 1.0), scale=2)
    expected = np.zeros((12, 20), dtype=bool)
    expected[1:11, 2:8] = np.repeat(np.repeat(FONT["1"], 2, axis=0), 2, axis=1)
    assert (painted(canvas) == expected).all()
    canvas.draw_text(-100, -100, "12")  # off the image: nothing, no error
    with pytest.raises(ValueError):
        canvas.draw_text(0, 0, "t = 1 h")


def test_text_bitmap_width():
    assert R.text_bitmap("10", scale=1).shape == (5, 3 + 1 + 3)
    assert R.text_bitmap("", scale=3).shape == (15, 0)


# -- ground ------------------------------------------------------------------


def test_ground_in_a_side_view_fills_below_the_plane():
    bounds = (np.array([-2.0, -1.0, -2.0]), np.array([2.0, 3.0, 2.0]))  # 25 px / m at 100 px
    canvas = Canvas(100, 100)
    camera = make_camera("xy", bounds, (100, 100))
    paint_planes(canvas, camera, [((0.0, 0.0, 0.0), (0.0, 2.0, 0.0))])
    # y = 0 is 3 m below the top: row 75.
    np.testing.assert_allclose(pixel_rgb(canvas, 50, 90), GROUND_RGB)
    np.testing.assert_allclose(pixel_rgb(canvas, 50, 60), BACKGROUND_RGB)
    np.testing.assert_allclose(pixel_rgb(canvas, 50, 75), GROUND_EDGE_RGB)


def test_ground_seen_from_above_in_an_orthographic_slice_is_not_drawn():
    canvas = Canvas(50, 50)
    camera = make_camera("xz", BOX, (50, 50))  # the slice is y = 2, above the ground
    paint_planes(canvas, camera, [((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))])
    np.testing.assert_allclose(canvas.rgb, np.broadcast_to(np.float32(BACKGROUND_RGB), (50, 50, 3)))


def test_ground_in_perspective_is_below_the_horizon():
    canvas = Canvas(60, 60)
    camera = make_camera("3d", BOX, (60, 60), elevation=5.0)  # the horizon is in view
    paint_planes(canvas, camera, [((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))])
    bottom = canvas.rgb[-1].astype(np.float64)
    top = canvas.rgb[0].astype(np.float64)
    np.testing.assert_allclose(top, np.broadcast_to(BACKGROUND_RGB, top.shape), atol=1e-6)
    assert np.abs(bottom - np.array(BACKGROUND_RGB)).max() > 0.05


def test_planes_are_checked():
    canvas = Canvas(10, 10)
    with pytest.raises(ValueError):
        paint_planes(canvas, make_camera("xy", BOX, (10, 10)), [((0, 0, 0), (0, 0, 0))])


def test_many_dots_and_long_lines_are_drawn_in_exact_batches(monkeypatch):
    rng = np.random.default_rng(6)
    centres = rng.uniform(0, 30, (50, 2))
    radii = rng.uniform(1, 4, 50)
    colours = rng.random((50, 4))
    whole = Canvas(30, 30)
    whole.draw_dots(centres, radii, colours)
    whole.draw_lines(centres[:25], centres[25:], (1.0, 1.0, 0.0))
    # the canvas module reads its batch sizes (the package only re-exports them)
    monkeypatch.setattr(raster_canvas, "DOT_CHUNK", 7)
    monkeypatch.setattr(raster_canvas, "LINE_SAMPLE_CHUNK", 40)
    batched = Canvas(30, 30)
    batched.draw_dots(centres, radii, colours)
    batched.draw_lines(centres[:25], centres[25:], (1.0, 1.0, 0.0))
    np.testing.assert_allclose(batched.rgb, whole.rgb, atol=1e-6)
