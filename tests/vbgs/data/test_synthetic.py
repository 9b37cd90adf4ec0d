
import numpy as np
import pytest
from scipy import ndimage

from vbgs.data.raycast import camera_rays, cast, distance_to_surfaces, render
from vbgs.data.scene import validate_scene
from vbgs.data.stereo import disparity_to_depth, stereo_motorcycle_frame
from vbgs.data.synthetic import (
    OBJECT_BACKGROUND,
    ORBIT_RADIUS,
    ORBIT_TARGET,
    make_scene,
    render_views,
    scene_primitives,
    walk_poses,
)
from vbgs.render.camera import project, unproject

SMALL = dict(size=40, n_train=6, n_test=3)


@pytest.fixture(scope="module", params=["object", "room", "walk"])
def scene(request):
    return make_scene(request.param, **SMALL)


def test_shapes_dtypes_and_counts(scene):
    validate_scene(scene)
    assert len(scene.train) == 6 and len(scene.test) == 3
    for f in scene.train + scene.test:
        assert f.rgb.shape == (40, 40, 3) and f.rgb.dtype == np.float32
        assert f.depth.shape == (40, 40) and f.depth.dtype == np.float32


def test_deterministic_under_seed(scene):
    again = make_scene(scene.name, **SMALL)
    other = make_scene(scene.name, **SMALL, seed=1)
    frames = zip(
        scene.train + scene.test, again.train + again.test, other.train + other.test, strict=True
    )
    for a, b, c in frames:
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.camera.pose, b.camera.pose)
        assert not np.array_equal(a.depth, c.depth)


def test_depth_is_exact(scene):
    prims = scene_primitives(scene.name)
    for f in scene.train + scene.test:
        xyz, _ = unproject(f.camera, f.rgb, f.depth)
        assert len(xyz) > 100
        assert distance_to_surfaces(prims, xyz).max() < 1e-4
        lo, hi = scene.bounds
        assert np.all(xyz >= lo - 1e-4) and np.all(xyz <= hi + 1e-4)


def test_sphere_surface_points_lie_on_the_sphere():
    scene = make_scene("object", **SMALL)
    sphere = next(p for p in scene_primitives("object") if type(p).__name__ == "Sphere")
    on_sphere = 0
    for f in scene.train:
        xyz, _ = unproject(f.camera, f.rgb, f.depth)
        d = np.abs(np.linalg.norm(xyz - np.asarray(sphere.centre), axis=1) - sphere.radius)
        near = d < 0.01
        on_sphere += near.sum()
        assert d[near].max() < 1e-5
    assert on_sphere > 200


def test_background_and_validity():
    obj = make_scene("object", **SMALL)
    for f in obj.train:
        missing = f.depth == 0
        assert 0.2 < missing.mean() < 0.95
        # a pixel's colour averages rays over its area: missing pixels away from every
        # surface pixel are pure background (silhouette pixels mix in the object)
        near_surface = ndimage.binary_dilation(~missing, structure=np.ones((3, 3)))
        empty = missing & ~near_surface
        assert empty.sum() > 0.5 * missing.sum()
        np.testing.assert_array_equal(
            f.rgb[empty], np.broadcast_to(OBJECT_BACKGROUND, (empty.sum(), 3))
        )
    assert obj.background == OBJECT_BACKGROUND
    room = make_scene("room", **SMALL)
    for f in room.train + room.test:
        assert np.all(f.depth > 0.1)


def _neighbours(name):
    """Two neighbouring training views of scene ``name``, one ray per pixel. The walk's 6
    frames would be 6.4 units apart: two of its 60 (0.54 apart), at 96 px, as its ground's
    depth changes fast from row to row near the horizon."""
    if name == "walk":
        return render_views("walk", walk_poses(60, 0)[0][:2], size=96, samples=1)
    return make_scene(name, **SMALL, samples=1).train[:2]


def test_views_agree_on_geometry_and_colour(scene):
    """Points seen from view A, where view B sees them too, have B's depth and colour
    (one ray per pixel, so a pixel's colour is the albedo at its centre's point)."""
    prims = scene_primitives(scene.name)
    a, b = _neighbours(scene.name)
    w, h = b.camera.width, b.camera.height
    xyz, rgb = unproject(a.camera, a.rgb, a.depth)  # [n, 3] each
    centre = b.camera.position
    t, albedo = cast(prims, centre, xyz.astype(np.float64) - centre)  # t = 1 at the point
    visible = np.abs(t - 1.0) < 1e-4
    uv, z = project(b.camera, xyz)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h) & (z > 0)
    both = visible & inside
    assert both.mean() > 0.3
    np.testing.assert_allclose(albedo[both], rgb[both], atol=2e-3)
    cols, rows = uv[both, 0].astype(int), uv[both, 1].astype(int)
    rel = np.abs(b.depth[rows, cols] - z[both]) / z[both]
    assert np.median(rel) < 0.01


def test_textures_are_real_photos(scene):
    rgb = np.concatenate([f.rgb[f.depth > 0] for f in scene.train])
    assert rgb.std(0).min() > 0.1
    assert len(np.unique(np.round(rgb * 255), axis=0)) > 500


def test_orbit_is_continuous_and_tests_are_off_it():
    scene = make_scene("object", size=8, n_train=30, n_test=5)
    centres = np.stack([f.camera.position for f in scene.train])
    radii = np.linalg.norm(centres - ORBIT_TARGET, axis=1)
    np.testing.assert_allclose(radii, ORBIT_RADIUS)
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert steps.max() < 2 * np.pi * ORBIT_RADIUS / 30 * 1.5
    elevation = np.arcsin((centres[:, 2] - ORBIT_TARGET[2]) / ORBIT_RADIUS)
    assert np.ptp(elevation) > np.deg2rad(30)
    for f in scene.test:
        gap = np.linalg.norm(centres - f.camera.position, axis=1).min()
        assert gap > 1e-3
        assert np.linalg.norm(f.camera.position - ORBIT_TARGET) == pytest.approx(ORBIT_RADIUS)


def test_unknown_scene_lists_known_names():
    with pytest.raises(ValueError, match="object, room"):
        make_scene("kitchen")


def test_stereo_motorcycle_frame():
    f = stereo_motorcycle_frame()
    assert f.rgb.shape == (500, 741, 3) and f.depth.shape == (500, 741)
    assert f.rgb.dtype == np.float32 and f.depth.dtype == np.float32
    assert np.all(np.isfinite(f.depth)) and np.all(np.isfinite(f.rgb))
    valid = f.depth > 0
    assert 0.85 < valid.mean() < 0.99
    assert 1.5 < f.depth[valid].min() and f.depth[valid].max() < 6.0  # metres
    assert 2.0 < np.median(f.depth[valid]) < 3.5
    assert f.camera.fx == pytest.approx(994.978)
    xyz, _ = unproject(f.camera, f.rgb, f.depth)
    assert np.all(np.isfinite(xyz))


def test_disparity_to_depth_marks_bad_disparity_missing():
    disp = np.array([[10.0, 0.0, np.nan, np.inf, -5.0]])
    depth = disparity_to_depth(disp, focal=100.0, baseline=0.5, doffs=0.0)
    np.testing.assert_allclose(depth, [[5.0, 0, 0, 0, 0]])
    assert disparity_to_depth(disp, 100.0, 0.5, doffs=10.0)[0, 1] == pytest.approx(5.0)


@pytest.mark.parametrize("name", ["object", "room", "walk"])
def test_culled_cast_equals_every_primitive_on_every_ray(name):
    """cast tests each primitive only on the rays near its bounding sphere: the hits and
    colours equal those of testing every ray against every primitive."""
    prims = scene_primitives(name)
    frame = make_scene(name, size=24, n_train=2, n_test=1, samples=1).train[1]
    dirs = camera_rays(frame.camera, samples=2)
    best_t, rgb = np.full(len(dirs), np.inf), np.zeros((len(dirs), 3))
    for prim in prims:
        t, uv = prim.hit(frame.camera.position, dirs)
        closer = t < best_t
        best_t[closer] = t[closer]
        rgb[closer] = prim.surface.colour(uv[closer])
    t, colours = cast(prims, frame.camera.position, dirs)
    assert np.isfinite(t).mean() > 0.3
    np.testing.assert_array_equal(t, best_t)
    np.testing.assert_array_equal(colours, rgb)


@pytest.mark.parametrize("samples", [2, 3])
def test_antialiased_pixels_average_their_sub_pixel_rays(samples):
    """A pixel's colour is the mean of samples x samples rays over its area; its depth is
    the centre ray's, the same as one ray per pixel gives."""
    prims = scene_primitives("object")
    cam = make_scene("object", size=20, n_train=1, n_test=1, samples=1).train[0].camera
    one_rgb, one_depth = render(prims, cam, OBJECT_BACKGROUND)
    rgb, depth = render(prims, cam, OBJECT_BACKGROUND, samples=samples)
    np.testing.assert_array_equal(depth, one_depth)
    t, albedo = cast(prims, cam.position, camera_rays(cam, samples))
    albedo[~np.isfinite(t)] = OBJECT_BACKGROUND
    expected = albedo.reshape(20, 20, samples * samples, 3).mean(2)
    np.testing.assert_allclose(rgb, expected, atol=1e-6)
    # sub-pixel rays lie inside their pixel: a pixel whose rays all hit one flat-coloured
    # background agrees with the single ray; silhouette pixels mix object and background
    hit = np.isfinite(t).reshape(20, 20, samples * samples)
    mixed = hit.any(-1) & ~hit.all(-1)
    assert mixed.sum() > 5
    empty = ~hit.any(-1)
    np.testing.assert_array_equal(rgb[empty], one_rgb[empty])
    assert np.all(np.abs(rgb[mixed] - one_rgb[mixed]).max(-1) > 0)


def test_samples_must_be_a_positive_integer():
    cam = make_scene("object", size=8, n_train=1, n_test=1).train[0].camera
    for bad in (0, -1, 1.5):
        with pytest.raises(ValueError, match="samples must be a positive integer"):
            render(scene_primitives("object"), cam, samples=bad)
