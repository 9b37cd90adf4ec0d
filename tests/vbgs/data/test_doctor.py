"""The dataset doctor on a synthetic trajectory broken the ways files break: each
mix-up fails its check and the fix that undoes it is the one named."""

import numpy as np
import pytest

from vbgs.data import doctor
from vbgs.data.formats import quaternion_to_matrix
from vbgs.data.synthetic import room_scene
from vbgs.render.camera import opengl_to_opencv
from vbgs.render.splats import quaternions_from_rotations


@pytest.fixture(scope="module")
def frames():
    return room_scene(size=32, n_train=12, n_test=1, n_val=0, seed=0).train


def posed(frames, edit):
    return doctor._with_poses(frames, [edit(np.array(f.camera.pose)) for f in frames])


def mm(p):
    p[:3, 3] *= 1000
    return p


def wxyz_read_as_xyzw(p):
    w, x, y, z = quaternions_from_rotations(p[None, :3, :3])[0]
    p[:3, :3] = quaternion_to_matrix(w, x, y, z)  # the file's qw qx qy qz read as qx qy qz qw
    return p


def test_a_clean_trajectory_is_healthy(frames):
    report = doctor.examine(frames)
    assert report.healthy and report.fix is None
    assert report.agreement > 0.8  # 0.86 measured
    assert [c.name for c in report.checks] == ["rotations", "intrinsics", "depth codes",
                                               "depth values", "depth scale", "consistency"]
    assert report.agreement >= doctor.NEAR_NOISE * report.expected


@pytest.mark.parametrize("edit, fix, format", [
    (np.linalg.inv, "w2c", None),
    (opengl_to_opencv, "axes", None),
    (lambda p: np.linalg.inv(opengl_to_opencv(p)), "w2c+axes", None),
    (mm, "depth x1000", None),  # the same geometry: every length of the depth x 1000
    (wxyz_read_as_xyzw, "quaternion-wxyz", "tum"),
], ids=["w2c", "axes", "w2c+axes", "mm", "quaternion"])
def test_each_pose_mix_up_fails_consistency_and_its_fix_is_named(frames, edit, fix, format):
    report = doctor.examine(posed(frames, edit), format)
    assert not report.healthy and report.checks[-1].ok is False
    assert report.fix_agreement >= (report.agreement or 0) + doctor.FIX_GAIN
    assert report.fix == fix and report.fix_agreement > 0.8


def test_millimetre_translations_fail_the_cheap_depth_scale_check(frames):
    check = doctor.check_depth_scale(posed(frames, mm))
    assert check.ok is False and "millimetres and metres" in check.message
    with pytest.raises(ValueError, match="depth scale: .* moves \\d+ median depths"):
        doctor.refuse_bad_cameras(posed(frames, mm))


def test_metres_in_a_millimetre_png_are_named(frames):
    metres = [f._replace(depth=(np.round(f.depth) / 1000).astype(np.float32)) for f in frames]
    check = doctor.check_depth_codes(metres, 1000.0)
    assert check.ok is False and "depth in metres written as whole numbers" in check.message
    assert doctor.check_depth_codes(frames, 1000.0).ok is not False  # mm codes: many values


@pytest.mark.parametrize("edit, words", [
    (lambda p: np.diag([2.0, 2, 2, 1]) @ p, "(scaled)"),
    (lambda p: p @ np.array([[1, .4, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.]]),
     "(sheared)"),
    (lambda p: p @ np.diag([-1.0, 1, 1, 1]), "determinant -1"),
])
def test_bad_rotations_are_named_per_frame(frames, edit, words):
    bad = list(frames)
    bad[3] = posed([frames[3]], edit)[0]
    check = doctor.check_rotations(bad)
    assert check.ok is False and check.frames == (3,) and words in check.message


@pytest.mark.parametrize("sensor", ["kinect", "realsense"])
def test_noisy_sensors_alone_do_not_fail_and_their_mix_ups_still_can(frames, sensor):
    """A sensor's noise lowers the agreement of every pose set alike, and of neighbouring
    pixels alike: the views stay healthy (RealSense at 32 px agrees at about 0.15 within
    5%, its pixels with their neighbours at 0.15); a world-to-camera mix-up on the same
    depth is still named under the Kinect, whose noise leaves a margin."""
    from vbgs.sensors import simulate

    noisy = [f._replace(depth=simulate(sensor, f.depth, f.camera, seed=[0, i]))
             for i, f in enumerate(frames)]
    report = doctor.examine(noisy)
    assert report.healthy and report.fix is None, report.checks[-1]
    if sensor != "realsense":
        assert doctor.examine(posed(noisy, np.linalg.inv)).fix == "w2c"


def test_a_networks_depth_is_not_healthy_and_no_fix_is_named(frames):
    """A network's depth, warped differently in each frame, agrees across views at 0.53
    where its smooth pixels agree with their neighbours at 0.73: not healthy, and no
    single fix explains it."""
    from vbgs.sensors import simulate

    mono = [f._replace(depth=simulate("mono", f.depth, f.camera, seed=[0, i]))
            for i, f in enumerate(frames)]
    report = doctor.examine(mono)
    assert not report.healthy and report.fix is None
    assert "no single fix explains it" in report.checks[-1].message


@pytest.mark.parametrize("factor, scale, words", [
    (5.0, 1000.0, "give --depth-scale 5000"),  # TUM's PNGs read at 1000 per metre
    (0.2, 5000.0, "give --depth-scale 1000"),  # millimetre PNGs read as TUM's
    (1000.0, None, "divide the depth by 1000"),  # .npy depth in millimetres
    (1e-3, None, "divide each pose's translation by 1000"),  # metres against mm
], ids=["x5", "/5", "x1000", "/1000"])
def test_depth_off_by_a_common_factor_is_named_with_its_scale(frames, factor, scale, words):
    scaled = [f._replace(depth=(f.depth * factor).astype(np.float32)) for f in frames]
    report = doctor.examine(scaled, depth_scale=scale)
    assert not report.healthy and report.fix == f"depth x{1 / factor:.4g}"
    assert words in report.fix_words and "(tried: agreement" in report.fix_words
    assert report.fix_agreement >= doctor.NEAR_NOISE * report.expected > report.agreement


@pytest.mark.parametrize("edit", [
    lambda f: f._replace(depth=np.where(f.depth > 0, 2.0, 0.0).astype(np.float32)),
    lambda f: f._replace(depth=np.ascontiguousarray(f.depth.T)),
], ids=["constant depth", "transposed depth"])
def test_depth_no_fix_explains_is_said_so(frames, edit):
    """Constant or transposed depth maps: no candidate fix brings the views to what their
    noise allows, so none is named (no world-to-camera poses, no focal length)."""
    report = doctor.examine([edit(f) for f in frames])
    check = report.checks[-1]
    assert not report.healthy and report.fix is None and check.ok is False
    assert "no single fix explains it" in check.message


def test_a_principal_point_outside_the_image_is_named(frames):
    bad = [f._replace(camera=f.camera._replace(cx=600.0)) for f in frames]
    check = doctor.check_intrinsics(bad)
    assert check.ok is False and "outside the 32x32 image" in check.message
    assert "field of view" in doctor.check_intrinsics(frames).message


def test_one_frame_is_not_measured_and_views_apart_fail(frames):
    assert doctor.check_consistency(frames[:1])[0].ok is None
    moved = np.array(frames[1].camera.pose)
    moved[0, 3] += 100.0  # a hundred units away: no depth lands on the other frame's
    apart = [frames[0], frames[1]._replace(camera=frames[1].camera._replace(pose=moved))]
    check, score, _ = doctor.check_consistency(apart)
    assert check.ok is False and score is None and "views apart" in check.message
