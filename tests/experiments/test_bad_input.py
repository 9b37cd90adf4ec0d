"""Data as users bring it: bad or unusual inputs, in-process through the
command-line entry points and the library. Every case ends one of three ways, each
asserted: refused before any work with one line on stderr and exit 2 (with --json one
object with an ``error`` field), or a clear ``SystemExit(2)`` from argparse, or accepted
with the right number in the record; no traceback, no input file changed, no output
written where it would destroy data.

Folders are written once per module from the synthetic room (24 px), copied per case
and corrupted; refusals come from loading, so no case compiles a learner.
"""

import hashlib
import json
import os
import shutil

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper
from PIL import Image
from skimage import io as skio

import experiments.tasks.scene_task as scene_task
from depth.cli import main as depth_main
from experiments.run import main
from vbgs.data.blender import write_blender
from vbgs.data.depth_png import read_depth_png, write_depth_png
from vbgs.data.images import read_rgb
from vbgs.data.scene import Frame, require_some_depth, validate_frame
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica, write_tum

GL = np.diag([1.0, -1, -1, 1])
FIT = ["--size", "24", "--components", "50"]


# --------------------------------------------------------------------------- helpers



@pytest.fixture(autouse=True)
def message_log(monkeypatch, request):
    """With VBGS_BAD_INPUT_LOG=PATH, each refusal's one line is appended to PATH as
    ``case<TAB>message`` (the closing note's list of cases and their messages)."""
    path = os.environ.get("VBGS_BAD_INPUT_LOG")
    if path:
        import experiments.run as run

        original = run.fail

        def logged(err, as_json=False):
            with open(path, "a") as log:
                log.write(f"{request.node.name}\t{err}\n")
            return original(err, as_json)

        monkeypatch.setattr(run, "fail", logged)
    yield

@pytest.fixture(scope="module")
def room():
    return room_scene(size=24, n_train=10, n_test=2, n_val=2, seed=0)


@pytest.fixture(scope="module")
def folders(room, tmp_path_factory):
    root = tmp_path_factory.mktemp("clean")
    return {"blender": write_blender(room, root / "blender"),
            "replica": write_replica(room.train, root / "replica" / "room0"),
            "tum": write_tum(room.train, root / "rgbd_dataset_freiburg1_room")}


@pytest.fixture
def reached(monkeypatch):
    """Stop a run where the learner would start: a case that reaches it passed every check."""
    def stop(task, **kw):
        raise ValueError(f"reached the fit with {task.method}")

    monkeypatch.setattr(scene_task, "run_scene", stop)


def digest(folder) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(folder)).encode() + p.read_bytes())
    return h.hexdigest()


def copy(folders, kind, tmp_path):
    src = folders[kind]
    out = tmp_path / (src.name if kind == "tum" else kind)
    shutil.copytree(src.parent if kind == "replica" else src,
                    out if kind != "replica" else tmp_path / "replica")
    return tmp_path / "replica" / "room0" if kind == "replica" else out


def refused(argv, capsys, words: str) -> dict:
    """Exit 2, one line on stderr (after any warning lines), a JSON error naming ``words``."""
    code = main([*argv, "--json"])
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "Traceback" not in out
    assert code == 2, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: "), err
    record = json.loads(out.strip().splitlines()[-1])
    assert words in record["error"], record["error"]
    return record


def edit_json(path, change):
    meta = json.loads(path.read_text())
    change(meta)
    path.write_text(json.dumps(meta))


# --------------------------------------------------------------------------- Blender: cameras


def split_meta(split="train", frame=None, **values):
    def change(meta):
        target = meta if frame is None else meta["frames"][frame]
        target.update(values)
    return split, change


def no_focal(**values):
    def change(meta):
        for k in ("fl_x", "fl_y", "camera_angle_x", "cx", "cy"):
            meta.pop(k, None)
        meta.update(values)
    return "train", change


def pose_edit(edit, split="train", frame=1):
    def change(meta):
        m = np.asarray(meta["frames"][frame]["transform_matrix"], float)
        meta["frames"][frame]["transform_matrix"] = edit(m)
    return split, change


def scaled(m):
    m[:3, :3] *= 2
    return m.tolist()


def sheared(m):
    m[:3, :3] = m[:3, :3] @ np.array([[1, 0.4, 0], [0, 1, 0], [0, 0, 1.0]])
    return m.tolist()


def reflected(m):
    m[:3, 0] *= -1
    return m.tolist()


def halved(m):
    m[:3, 1] *= 0.5
    return m.tolist()


BLENDER_META = [
    ("fl_x 0, no angle", no_focal(fl_x=0), "positive 'fl_x'"),
    ("fl_x negative, no angle", no_focal(fl_x=-20), "positive 'fl_x'"),
    ("fl_x as text", split_meta(fl_x="41.7"), "'fl_x' is '41.7', not a number"),
    ("fl_y as text", split_meta(fl_y="41.7"), "'fl_y' is '41.7', not a number"),
    ("cx as text", split_meta(cx="12"), "'cx' is '12', not a number"),
    ("w as text", split_meta(w="24"), "'w' is '24', not a number"),
    ("angle as text", no_focal(camera_angle_x="0.8"), "not a number"),
    ("angle as a list", no_focal(camera_angle_x=[0.8]), "not a number"),
    ("angle true", no_focal(camera_angle_x=True), "not a number"),
    ("angle in degrees", no_focal(camera_angle_x=39.6), "in degrees? 39.6 degrees"),
    ("angle 90 degrees", no_focal(camera_angle_x=90), "in degrees? 90 degrees"),
    ("angle 0", no_focal(camera_angle_x=0), "'camera_angle_x' is 0"),
    ("angle negative", no_focal(camera_angle_x=-0.8), "in (0, pi)"),
    ("angle pi", no_focal(camera_angle_x=np.pi), "in (0, pi)"),
    ("angle 200", no_focal(camera_angle_x=200), "in (0, pi)"),
    ("angle_y degrees", split_meta(camera_angle_y=45.0), "'camera_angle_y' is 45.0"),
    ("fl_y 0", split_meta(fl_y=0), "'fl_y' is 0; it must be > 0"),
    ("fl_y negative", split_meta(fl_y=-3), "'fl_y' is -3"),
    ("w 0", split_meta(w=0), "'w' is 0; it must be > 0"),
    ("h negative", split_meta(h=-24), "'h' is -24"),
    ("frame fl_x text", split_meta(frame=2, fl_x="41.7"), "frame 2"),
    ("test split fl_x text", split_meta("test", fl_x="x"), "transforms_test.json"),
    ("val split angle degrees", split_meta("val", camera_angle_x=60.0), "in degrees?"),
    ("principal point outside", split_meta(cx=500.0), "principal point (500.0"),
    ("principal point negative", split_meta(cy=-40.0), "principal point"),
    ("rotation x2", pose_edit(scaled), "lengths [2.0, 2.0, 2.0] (scaled)"),
    ("one axis halved", pose_edit(halved), "(scaled)"),
    ("sheared", pose_edit(sheared), "not perpendicular (sheared)"),
    ("reflection", pose_edit(reflected), "determinant -1 (a reflection)"),
    ("test rotation x2", pose_edit(scaled, "test", 0), "(scaled)"),
    ("val reflection", pose_edit(reflected, "val", 0), "determinant -1"),
    ("test sheared", pose_edit(sheared, "test", 1), "(sheared)"),
    ("pose NaN", pose_edit(lambda m: [[float("nan")] * 4] + m.tolist()[1:]), "NaN/inf"),
    ("pose inf", pose_edit(lambda m: m.tolist()[:3] + [[0, 0, 0, float("inf")]]), "NaN/inf"),
    ("pose 3x4", pose_edit(lambda m: m.tolist()[:3]), "must be 4x4"),
    ("pose flat", pose_edit(lambda m: m.ravel().tolist()), "must be 4x4"),
    ("pose zeros", pose_edit(lambda m: np.zeros((4, 4)).tolist()), "(scaled)"),
    ("frames not a list", split_meta(frames=7), "not a transforms file"),
    ("no file_path", split_meta(frames=[{"transform_matrix": np.eye(4).tolist()}]),
     "needs 'file_path' and 'transform_matrix'"),
    ("no transform_matrix", split_meta(frames=[{"file_path": "./train/r_000"}]),
     "needs 'file_path' and 'transform_matrix'"),
    ("frame is a string", split_meta(frames=["./train/r_000"]), "needs 'file_path'"),
    ("image missing", split_meta(frames=[{"file_path": "./train/nope",
                                          "transform_matrix": np.eye(4).tolist()}]),
     "image './train/nope' not found"),
]


@pytest.mark.parametrize("name, split_change, words", BLENDER_META,
                         ids=[c[0] for c in BLENDER_META])
def test_blender_cameras_refused(folders, tmp_path, capsys, name, split_change, words):
    folder = copy(folders, "blender", tmp_path)
    split, change = split_change
    edit_json(folder / f"transforms_{split}.json", change)
    before = digest(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys, words)
    assert digest(folder) == before  # nothing written into the dataset


# --------------------------------------------------------------------------- Blender: files


def remove(rel):
    return lambda f: (f / rel).unlink()


def write_text(rel, text):
    return lambda f: (f / rel).write_text(text)


def truncate(rel):
    def change(f):
        data = (f / rel).read_bytes()
        (f / rel).write_bytes(data[: len(data) // 3])
    return change


def depth_as(rel, array):
    return lambda f: skio.imsave(f / rel, array, check_contrast=False)


def depth_metres(f):
    for png in f.glob("*/*_depth.png"):
        write_depth_png(png, np.round(read_depth_png(png)), 1.0)


def depth_zero(rel):
    return lambda f: write_depth_png(f / rel, np.zeros((24, 24)))


def clear(f):
    for p in f.iterdir():
        shutil.rmtree(p) if p.is_dir() else p.unlink()


BLENDER_FILES = [
    ("no transforms_train.json", remove("transforms_train.json"), "transforms_train.json not found"),
    ("no test split", lambda f: [remove("transforms_test.json")(f),
                                 (f / "transforms_val.json").rename(f / "val.json")],
     "neither transforms_test.json"),
    ("train json not json", write_text("transforms_train.json", "{frames: ["),
     "not a transforms file"),
    ("train json a list", write_text("transforms_train.json", "[]"), "not a transforms file"),
    ("train json empty", write_text("transforms_train.json", ""), "not a transforms file"),
    ("image missing", remove("train/r_003.png"), "r_003' not found"),
    ("image is text", write_text("train/r_002.png", "not an image"), "could not read image"),
    ("image truncated", truncate("train/r_001.png"), "could not read image"),
    ("depth missing", remove("train/r_004_depth.png"), "no depth for"),
    ("depth 8-bit", depth_as("train/r_000_depth.png", np.full((24, 24), 9, np.uint8)),
     "this one is 8-bit"),
    ("depth colour", depth_as("train/r_000_depth.png",
                              np.dstack([np.full((24, 24), v, np.uint8) for v in (1, 2, 3)])),
     "a colour image, not a depth map"),
    ("depth truncated", truncate("train/r_000_depth.png"), "could not read image"),
    ("depth all missing", depth_zero("train/r_002_depth.png"), "depth is 0 (missing) at every"),
    ("depth wrong size", lambda f: write_depth_png(f / "train/r_000_depth.png",
                                                   np.ones((12, 12))),
     "depth has shape (12, 12), expected (24, 24)"),
    ("depth metres in 16-bit PNG", depth_metres, "depth in metres written as whole numbers"),
    ("test depth missing", remove("test/r_000_depth.png"), "no depth for"),
    ("empty folder", clear, "cannot tell the dataset format"),
]


@pytest.mark.parametrize("name, change, words", BLENDER_FILES, ids=[c[0] for c in BLENDER_FILES])
def test_blender_files_refused(folders, tmp_path, capsys, name, change, words):
    folder = copy(folders, "blender", tmp_path)
    change(folder)
    before = digest(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys, words)
    assert digest(folder) == before


# --------------------------------------------------------------------------- conventions (doctor)


def poses_everywhere(edit):
    def change(folder):
        for split in ("train", "test", "val"):
            def each(meta):
                for f in meta["frames"]:
                    f["transform_matrix"] = edit(np.asarray(f["transform_matrix"])).tolist()
            edit_json(folder / f"transforms_{split}.json", each)
    return change


def mm(m):
    m = m.copy()
    m[:3, 3] *= 1000
    return m


CONVENTIONS = [
    ("w2c", poses_everywhere(np.linalg.inv), "consistency", "world-to-camera: invert each"),
    ("opencv axes in a nerf file", poses_everywhere(lambda m: m @ GL), "consistency",
     "multiply each pose on the right by diag(1, -1, -1, 1)"),
    ("w2c in opencv axes", poses_everywhere(lambda m: np.linalg.inv(m @ GL)), "consistency",
     "world-to-camera in the other axis convention"),
    ("translations in mm", poses_everywhere(mm), "depth scale",
     "divide each pose's translation by 1000"),
    ("depth metres in png", depth_metres, "depth codes", "metres written as whole numbers"),
]


@pytest.mark.parametrize("name, change, check, fix", CONVENTIONS, ids=[c[0] for c in CONVENTIONS])
def test_the_doctor_names_each_convention_mix_up(folders, tmp_path, capsys, name, change,
                                                 check, fix):
    folder = copy(folders, "blender", tmp_path)
    change(folder)
    record = refused(["check", "--scene", str(folder), "--size", "24"], capsys, fix)
    assert record["error"].startswith(f"{check}: ") and record["healthy"] is False


def test_the_doctor_passes_the_clean_folders(folders, room, capsys):
    for kind, folder in folders.items():  # TUM has no file for them: the camera is given
        given = ["--intrinsics", tum_intrinsics(room)] if kind == "tum" else []
        assert main(["check", "--scene", str(folder), "--size", "24", *given, "--json"]) == 0
        record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert record["healthy"] and record["agreement"] > 0.7, (kind, record)


# --------------------------------------------------------------------------- Replica


def traj_lines(edit):
    def change(folder):
        lines = (folder / "traj.txt").read_text().splitlines()
        (folder / "traj.txt").write_text("\n".join(edit(lines)) + "\n")
    return change


def traj_pose(edit):
    def each(lines):
        out = []
        for line in lines:
            m = np.asarray([float(v) for v in line.split()]).reshape(4, 4)
            out.append(" ".join(f"{v:.9g}" for v in edit(m).ravel()))
        return out
    return traj_lines(each)


def cam_params(**camera):
    def change(folder):
        path = folder / "cam_params.json"
        meta = json.loads(path.read_text())
        meta["camera"].update(camera)
        path.write_text(json.dumps(meta))
    return change


def scale_rotation(m):
    m[:3, :3] *= 2
    return m


REPLICA = [
    ("no results folder", lambda f: shutil.rmtree(f / "results"), "results not found"),
    ("no frames", lambda f: [p.unlink() for p in (f / "results").glob("frame*.jpg")],
     "no frame*.jpg images"),
    ("no traj.txt", remove("traj.txt"), "traj.txt not found"),
    ("traj short", traj_lines(lambda lines: lines[:-1]), "traj.txt has 9 poses for 10"),
    ("traj 15 numbers", traj_lines(lambda lines: [lines[0].rsplit(" ", 1)[0]] + lines[1:]),
     "expected 16 numbers"),
    ("traj text", traj_lines(lambda lines: ["a " * 16] + lines[1:]), "expected 16 numbers"),
    ("traj NaN", traj_lines(lambda lines: [" ".join(["nan"] * 16)] + lines[1:]), "NaN/inf"),
    ("traj rotation x2", traj_pose(scale_rotation), "(scaled)"),
    ("depth missing", remove("results/depth000003.png"), "has no depth image"),
    ("cam_params not json", write_text("cam_params.json", "{"), "cam_params.json: expected"),
    ("cam_params no camera", write_text("cam_params.json", "{}"), "cam_params.json: expected"),
    ("cam_params fx text", cam_params(fx="600"), "camera fx is '600'"),
    ("cam_params scale 0", cam_params(scale=0), "camera.scale must be > 0"),
    ("cam_params w 0", cam_params(w=0), "camera.w and camera.h must be > 0"),
    ("cam_params negative focal", cam_params(fy=-1), "focal lengths must be > 0"),
    ("translations in mm", traj_pose(mm), "depth scale"),
]


@pytest.mark.parametrize("name, change, words", REPLICA, ids=[c[0] for c in REPLICA])
def test_replica_refused(folders, tmp_path, capsys, name, change, words):
    folder = copy(folders, "replica", tmp_path)
    change(folder)
    before = digest(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys, words)
    assert digest(folder) == before


@pytest.mark.parametrize("name, change, words", [
    ("w2c", traj_pose(np.linalg.inv), "world-to-camera"),
    ("opengl axes", traj_pose(lambda m: m @ GL), "diag(1, -1, -1, 1)"),
    ("another camera's intrinsics", cam_params(fx=9.0, fy=9.0), "intrinsics are another camera's"),
], ids=["w2c", "opengl axes", "another camera"])
def test_replica_conventions_named_by_the_doctor(folders, tmp_path, capsys, name, change, words):
    folder = copy(folders, "replica", tmp_path)
    change(folder)
    refused(["check", "--scene", str(folder), "--size", "24"], capsys, words)


# --------------------------------------------------------------------------- TUM


def tum_lines(name, edit):
    def change(folder):
        lines = (folder / name).read_text().splitlines()
        (folder / name).write_text("\n".join([lines[0], *edit(lines[1:])]) + "\n")
    return change


def wxyz(lines):
    out = []
    for line in lines:
        t, x, y, z, qx, qy, qz, qw = line.split()
        out.append(" ".join([t, x, y, z, qw, qx, qy, qz]))
    return out


TUM = [
    ("no rgb.txt", remove("rgb.txt"), "rgb.txt not found"),
    ("no groundtruth", remove("groundtruth.txt"), "groundtruth.txt not found"),
    ("groundtruth short line", tum_lines("groundtruth.txt", lambda ls: [ls[0][:40]] + ls[1:]),
     "expected a timestamp and 7 value(s)"),
    ("rgb.txt empty", write_text("rgb.txt", "# nothing\n"), "rgb.txt lists no entries"),
    ("poses an hour late", tum_lines("groundtruth.txt", lambda ls: [
        f"{float(line.split()[0]) + 3600:.6f} {line.split(' ', 1)[1]}" for line in ls]),
     "no rgb image has both a depth image and a pose"),
    ("depth file missing", lambda f: next((f / "depth").glob("*.png")).unlink(),
     "depth image not found"),
    ("quaternion zero", tum_lines("groundtruth.txt", lambda ls: [
        " ".join(line.split()[:4] + ["0"] * 4) for line in ls]), "has no direction"),
    ("quaternion NaN", tum_lines("groundtruth.txt", lambda ls: [
        " ".join(line.split()[:4] + ["nan"] * 4) for line in ls]), "has no direction"),
]


@pytest.mark.parametrize("name, change, words", TUM, ids=[c[0] for c in TUM])
def test_tum_refused(folders, tmp_path, capsys, name, change, words):
    folder = copy(folders, "tum", tmp_path)
    change(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys, words)


def tum_intrinsics(room) -> str:
    cam = room.train[0].camera
    return f"{cam.fx},{cam.fy},{cam.cx - 0.5},{cam.cy - 0.5}"


def test_tum_quaternion_order_is_named(folders, room, tmp_path, capsys):
    folder = copy(folders, "tum", tmp_path)
    tum_lines("groundtruth.txt", wxyz)(folder)
    refused(["check", "--scene", str(folder), "--size", "24", "--intrinsics",
             tum_intrinsics(room)], capsys, "written qw qx qy qz")


@pytest.mark.parametrize("name, preset", [("rgbd_dataset_freiburg1_room", "fr1"),
                                          ("rgbd_dataset_freiburg2_room", "fr2"),
                                          ("rgbd_dataset_freiburg3_room", "fr3"),
                                          ("my_room", "fr1")])
def test_tum_intrinsics_follow_the_folder_name_and_are_reported(folders, tmp_path, capsys,
                                                                name, preset):
    folder = tmp_path / name
    shutil.copytree(folders["tum"], folder)
    main(["check", "--scene", str(folder), "--size", "24", "--json"])
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    fx = {"fr1": 517.3, "fr2": 520.9, "fr3": 535.4}[preset]
    assert record["intrinsics_given"][0] == fx and preset in record["intrinsics_from"]
    assert record["intrinsics"][0] == pytest.approx(fx * 24 / 640)
    assert record["depth_scale"] == 5000


def test_given_intrinsics_are_used_and_reported(folders, room, capsys):
    assert main(["check", "--scene", str(folders["tum"]), "--size", "24", "--intrinsics",
                 tum_intrinsics(room), "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert record["intrinsics_from"] == "--intrinsics" and record["healthy"]
    assert record["intrinsics"][0] == pytest.approx(room.train[0].camera.fx)


# --------------------------------------------------------------------------- what the doctor sees


def each_line(name, edit):
    """Rewrite every entry line of a TUM list file (the comment line kept)."""
    return tum_lines(name, lambda lines: [out for line in lines for out in edit(line)])


def later(seconds):
    return lambda line: [f"{float(line.split()[0]) + seconds:.6f} {line.split()[1]}"]


def frozen(folder):
    first = (folder / "depth.txt").read_text().splitlines()[1].split()[1]
    each_line("depth.txt", lambda line: [f"{line.split()[0]} {first}"])(folder)


# Folders the doctor must not call healthy: (name, kind, change, extra flags, words).
UNHEALTHY = [
    ("duplicated frames", "tum", each_line("rgb.txt", lambda line: [line, line]), [],
     "duplicates: 2 of 2 test views"),
    ("depth 30 ms late", "tum", each_line("depth.txt", later(0.03)), [],
     "subtract 0.033 s from depth.txt's stamps (tried: agreement"),
    ("frozen depth", "tum", frozen, [], "frozen depth: 8 of 8 frames share"),
    ("depth scale x5", "tum", lambda f: None, ["--depth-scale", "1000"],
     "give --depth-scale 5000 (read at 1000 the depth is 5 x too long) (tried: agreement"),
    ("depth scale /5", "replica", cam_params(scale=6553.5 * 5), [],
     "give --depth-scale 6553.5 (read at 32767.5 the depth is 5 x too short)"),
    ("another camera's aspect", "replica", cam_params(w=640, h=480, cx=319.5, cy=239.5), [],
     "describes 640x480 images (aspect 1.333) and these are 24x24"),
    ("half the poses", "tum", tum_lines("groundtruth.txt", lambda ls: ls[: len(ls) // 2]), [],
     "5 have no pose (groundtruth.txt covers"),
]


@pytest.mark.parametrize("name, kind, change, extra, words", UNHEALTHY,
                         ids=[c[0] for c in UNHEALTHY])
def test_the_doctor_calls_none_of_these_healthy(folders, room, tmp_path, capsys, name, kind,
                                                change, extra, words):
    folder = copy(folders, kind, tmp_path)
    change(folder)
    given = ["--intrinsics", tum_intrinsics(room)] if kind == "tum" else []
    record = refused(["check", "--scene", str(folder), "--size", "24", *given, *extra],
                     capsys, words)
    assert record["healthy"] is False
    if "tried: agreement" in words:  # the fix named was tried and reached what the noise allows
        assert record["fix_agreement"] >= 0.8 * record["expected_agreement"] > record[
            "agreement"]


@pytest.fixture
def stopped(monkeypatch):
    """Stop a run where the learner is built: after the scene's checks and warnings."""
    monkeypatch.setitem(scene_task.LEARNERS, "vbgs", StopLearner)


def test_a_score_from_leaked_test_views_is_refused(folders, room, tmp_path, capsys, stopped):
    folder = copy(folders, "tum", tmp_path)
    each_line("rgb.txt", lambda line: [line, line])(folder)
    before = digest(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT, "--intrinsics", tum_intrinsics(room)],
            capsys, "every one of the 2 test views is bit-identical to a training frame")
    assert digest(folder) == before


@pytest.mark.parametrize("name, kind, change, words", [
    ("frozen depth", "tum", frozen, "frozen depth: 8 of 8 frames share"),
    ("another camera's aspect", "replica", cam_params(w=640, h=480, cx=319.5, cy=239.5),
     "camera size: "),
], ids=["frozen depth", "aspect"])
def test_fit_scene_refuses_what_no_run_can_use(folders, room, tmp_path, capsys, stopped, name,
                                               kind, change, words):
    folder = copy(folders, kind, tmp_path)
    change(folder)
    given = ["--intrinsics", tum_intrinsics(room)] if kind == "tum" else []
    refused(["fit-scene", "--scene", str(folder), *FIT, *given], capsys, words)


def test_fit_scene_says_which_frames_it_left_out(folders, room, tmp_path, capsys, stopped):
    """Half the poses: the frames without one are left out (the TUM association rule),
    said on stderr; depth 30 ms late: the re-pairing that makes the views agree named."""
    folder = copy(folders, "tum", tmp_path)
    tum_lines("groundtruth.txt", lambda ls: ls[: len(ls) // 2])(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT, "--intrinsics", tum_intrinsics(room)],
            capsys, "stopped with 4 training frame(s)")
    folder = copy(folders, "tum", tmp_path / "late")
    each_line("depth.txt", later(0.03))(folder)
    main(["fit-scene", "--scene", str(folder), *FIT, "--intrinsics", tum_intrinsics(room)])
    err = capsys.readouterr().err
    assert "warning: consistency: only" in err and "subtract 0.033 s from depth.txt" in err


def test_fit_scene_warns_on_half_the_poses(folders, room, tmp_path, capsys, stopped):
    folder = copy(folders, "tum", tmp_path)
    tum_lines("groundtruth.txt", lambda ls: ls[: len(ls) // 2])(folder)
    main(["fit-scene", "--scene", str(folder), *FIT, "--intrinsics", tum_intrinsics(room)])
    err = capsys.readouterr().err
    assert "warning: pairing: 5 of 10 rgb images paired" in err and "are left out" in err


def test_a_folder_of_two_formats_is_refused(folders, tmp_path, capsys, stopped):
    folder = copy(folders, "tum", tmp_path)
    shutil.copy(folders["blender"] / "transforms_train.json", folder)
    refused(["check", "--scene", str(folder), "--size", "24"], capsys,
            "holds the files of 2 dataset formats")


@pytest.mark.parametrize("name, weights, bias, words", [
    ("1e9 everywhere", (0.0, 0.0, 0.0), 1e9, "the model's output is 1e+09 at every finite pixel"),
    ("NaN", (0.0, 0.0, 0.0), float("nan"), "the model's output is NaN or infinite at all"),
    ("negative", (-1.0, -1.0, -1.0), -0.1, "the model's output spans -3.1 to"),
    ("zero", (0.0, 0.0, 0.0), 0.0, "the model's output spans 0 to 0: no pixel is > 0"),
], ids=["1e9", "nan", "negative", "zero"])
def test_a_depth_model_whose_output_is_no_depth_is_named(tmp_path, capsys, name, weights,
                                                         bias, words):
    from depth.testing import channel_sum_model

    path = tmp_path / "model.onnx"
    onnx.save(channel_sum_model(weights, bias), path)
    refused(["fit-scene", "--scene", "object", "--size", "16", "--components", "20",
             "--frames", "4", "--depth-model", str(path), "--depth-kind", "metric"], capsys,
            f"--depth-model, frame 0: {words}")


def test_depth_scale_for_npy_depth_is_refused(room, tmp_path, capsys):
    """A .npy folder's depth is read as it is: a --depth-scale would be recorded as used and
    change nothing."""
    folder = write_blender(room, tmp_path / "npy", depth="npy")
    refused(["fit-scene", "--scene", str(folder), *FIT, "--depth-scale", "1000"], capsys,
            "--depth-scale 1000 converts 16-bit PNG depth codes to scene units, but")


def test_tiny_frames_run_with_a_warning(capsys, stopped):
    refused(["fit-scene", "--scene", "object", "--size", "1", "--components", "2",
             "--frames", "4", "--test-views", "1"], capsys, "stopped with 4 training")
    main(["fit-scene", "--scene", "object", "--size", "1", "--components", "2", "--frames",
          "4", "--test-views", "1"])
    assert "frames of 1x1 pixels: a score over so few pixels measures next to nothing" in \
        capsys.readouterr().err


def test_a_still_camera_is_named_and_its_leaked_views_refused(room, tmp_path, capsys,
                                                              stopped):
    """Twelve identical frames: the duplicates said on stderr, the score refused."""
    still = room._replace(train=[room.train[0]] * 12, test=[room.train[0]],
                          val=[room.train[0]])
    folder = write_blender(still, tmp_path / "still")
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys,
            "every one of the 1 test views is bit-identical to a training frame")
    main(["fit-scene", "--scene", str(folder), *FIT])
    assert "every frame is the same image: a still camera" in capsys.readouterr().err


def test_tune_refuses_a_repeated_grid_value(capsys):
    refused(["tune", "--scene", "object", "--size", "24", "--components", "50", "--frames",
             "4", "--grid", "splat_scale=1.0,1.2,1.0"], capsys,
            "--grid splat_scale: 1.0 is listed more than once")


def test_write_scene_refuses_a_level_for_the_exact_sensor(tmp_path, capsys):
    out = tmp_path / "folder"
    refused(["write-scene", "--scene", "object", "--size", "16", "--out", str(out),
             "--sensor-level", "2"], capsys, "the folder would record the level")
    assert not out.exists()


def test_a_sweep_refuses_a_simulated_sensor_on_an_image_cell():
    from experiments.sweep.rules import apply_rules

    verdict = apply_rules({"task": "image", "dataset": "astronaut", "method": "vbgs",
                           "simulate_sensor": "kinect"})
    assert verdict.settings is None and "an image has no depth" in verdict.reason
    assert apply_rules({"task": "image", "dataset": "astronaut", "method": "vbgs",
                        "simulate_sensor": "exact"}).settings is not None


# --------------------------------------------------------------------------- flags


OBJECT = ["fit-scene", "--scene", "object", "--size", "24", "--components", "50", "--frames",
          "4", "--test-views", "1"]

FLAGS = [
    ("drift with given poses", ["--drift", "0.01,0.5"],
     "--drift sets the error of the simulated odometry of --poses odometry"),
    ("drift with tracked poses", ["--drift", "0.01,0.5", "--poses", "track"],
     "with --poses given or track there is none"),
    ("sensor level without a sensor", ["--sensor-level", "2"],
     "no noisy sensor is simulated (--simulate-sensor exact)"),
    ("sensor level with exact", ["--sensor-level", "0.5", "--sensor", "exact"],
     "--sensor-level scales a sensor's noise, but no noisy sensor"),
    ("size beyond memory", ["--size", "100000"], "give a smaller --size"),
    ("depth-scale 0", ["--depth-scale", "0"], "--depth-scale must be > 0"),
    ("depth-scale negative", ["--depth-scale", "-1000"], "--depth-scale must be > 0"),
    ("depth-scale nan", ["--depth-scale", "nan"], "give a finite number"),
    ("depth-scale inf", ["--depth-scale", "inf"], "give a finite number"),
    ("intrinsics three", ["--intrinsics", "1,2,3"], "four numbers"),
    ("intrinsics text", ["--intrinsics", "a,b,c,d"], "four numbers"),
    ("intrinsics focal 0", ["--intrinsics", "0,1,1,1"], "focal lengths must be > 0"),
    ("intrinsics cx negative", ["--intrinsics", "10,10,-1,1"], ">= 0"),
    ("intrinsics nan", ["--intrinsics", "nan,1,1,1"], "finite"),
    ("intrinsics five", ["--intrinsics", "1,1,1,1,1"], "four numbers"),
    ("replay with vbgs", ["--replay", "full"], "--replay applies to the gradient baseline"),
    ("replay none with vbgs", ["--replay", "none"], "--replay applies"),
    ("replay fifo with vbgs", ["--replay", "fifo:4"], "--replay applies"),
    ("steps with vbgs", ["--steps", "10"], "--steps applies to the gradient baseline"),
    ("steps-per-frame with vbgs", ["--steps-per-frame", "5"], "--steps-per-frame applies"),
    ("protocol static with vbgs", ["--protocol", "static"], "--protocol static applies"),
    ("opacity without constant", ["--opacity", "0.5"], "--opacity sets the opacity of"),
    ("opacity with evidence", ["--opacity", "0.9", "--opacity-rule", "evidence"],
     "--opacity-rule constant"),
    ("depth-kind without model", ["--depth-kind", "metric"], "--depth-kind describes"),
    ("depth-preset without model", ["--depth-preset", "x"], "--depth-preset names"),
    ("depth-align without model", ["--depth-align", "none"], "--depth-align aligns"),
    ("replay abbreviated", ["--rep", "full"], "--replay applies"),
    ("replay = form", ["--replay=full"], "--replay applies"),
    ("components 0", ["--components", "0"], "components must be a positive integer"),
    ("frames 0", ["--frames", "0"], "frames must be a positive integer"),
    ("components text", ["--components", "many"], "components must be a positive integer"),
    ("test views 0", ["--test-views", "0"], "--test-views must be at least 1"),
    ("splat blur 20", ["--splat-blur", "20"], "splat_blur must be"),
    ("splat blur negative", ["--splat-blur", "-1"], "splat_blur must be"),
    ("sensor level negative", ["--sensor-level", "-1"], "sensor_level must be"),
    ("sensor level nan", ["--sensor-level", "nan"], "sensor_level must be"),
    ("background two values", ["--background", "1,2"], "background"),
    ("background a name", ["--background", "red"], "background"),
    ("background above 1", ["--background", "2,0,0"], "background"),
    ("unknown sensor", ["--sensor", "bogus"], "sensor"),
    ("unknown simulated sensor", ["--simulate-sensor", "bogus"], "simulate_sensor"),
    ("simulated sensor and model", ["--simulate-sensor", "kinect", "--depth-model", "m.onnx"],
     "give one of them"),
    ("intrinsics on synthetic", ["--intrinsics", "20,20,12,12"], "apply to dataset folders"),
    ("depth scale on synthetic", ["--depth-scale", "1000"], "apply to dataset folders"),
    ("as many components as pixels", ["--components", "2304"], "is not fewer than"),
]


@pytest.mark.parametrize("name, extra, words", FLAGS, ids=[c[0] for c in FLAGS])
def test_flags_refused(capsys, reached, name, extra, words):
    refused([*OBJECT, *extra], capsys, words)


ACCEPTED = [
    ("protocol continual with vbgs", ["--protocol", "continual"], "vbgs"),
    ("opacity with constant", ["--opacity", "0.5", "--opacity-rule", "constant"], "vbgs"),
    ("gradient static", ["--method", "gradient", "--protocol", "static", "--steps", "5"],
     "gradient"),
    ("gradient replay", ["--method", "gradient", "--replay", "full"], "gradient"),
    ("gradient steps per frame", ["--method", "gradient", "--steps-per-frame", "3"],
     "gradient"),
    ("depth-align default value given", ["--depth-align", "auto", "--depth-model", "m.onnx"],
     "vbgs"),
]


@pytest.mark.parametrize("name, extra, method", ACCEPTED, ids=[c[0] for c in ACCEPTED])
def test_flags_that_apply_reach_the_fit(capsys, reached, name, extra, method):
    refused([*OBJECT, *extra], capsys, f"reached the fit with {method}")


ARGPARSE = [
    ("format unknown", ["--format", "colmap"]),
    ("method unknown", ["--method", "nerf"]),
    ("size 0", ["--size", "0"]),
    ("depth-scale text", ["--depth-scale", "mm"]),
    ("order unknown", ["--order", "backwards"]),
    ("unknown flag", ["--frobnicate"]),
    ("size float", ["--size", "24.5"]),
    ("unknown init", ["--init", "bogus"]),
]


@pytest.mark.parametrize("name, extra", ARGPARSE, ids=[c[0] for c in ARGPARSE])
def test_argparse_refusals_are_exit_2_without_traceback(capsys, reached, name, extra):
    with pytest.raises(SystemExit) as stop:
        main([*OBJECT, *extra])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "error:" in err and "Traceback" not in err


# --------------------------------------------------------------------------- scenes and outputs


def where(kind, tmp_path, folders):
    if kind == "missing":
        return str(tmp_path / "nope")
    if kind == "empty":
        (tmp_path / "empty").mkdir()
        return str(tmp_path / "empty")
    if kind == "file":
        (tmp_path / "notes.txt").write_text("x")
        return str(tmp_path / "notes.txt")
    return str(folders[kind])


SCENES = [
    ("missing folder", "missing", [], "neither a dataset folder nor a built-in scene"),
    ("empty folder", "empty", [], "cannot tell the dataset format"),
    ("a file", "file", [], "neither a dataset folder nor a built-in scene"),
    ("blender read as replica", "blender", ["--format", "replica"], "results not found"),
    ("blender read as tum", "blender", ["--format", "tum"], "rgb.txt not found"),
    ("replica read as blender", "replica", ["--format", "blender"], "transforms_train.json"),
    ("tum read as replica", "tum", ["--format", "replica"], "results not found"),
]


@pytest.mark.parametrize("name, kind, extra, words", SCENES, ids=[c[0] for c in SCENES])
@pytest.mark.parametrize("command", ["fit-scene", "check"])
def test_scenes_that_are_not_datasets(folders, tmp_path, capsys, command, name, kind, extra,
                                      words):
    argv = [command, "--scene", where(kind, tmp_path, folders), "--size", "24", *extra]
    refused(argv + (["--components", "50"] if command == "fit-scene" else []), capsys, words)


CHECK = [
    ("size negative", ["--size", "-1"], "--size must be >= 0"),
    ("frames 0", ["--frames", "0"], "--frames >= 1"),
    ("depth scale 0", ["--depth-scale", "0"], "--depth-scale must be > 0"),
    ("intrinsics bad", ["--intrinsics", "1,2"], "four numbers"),
]


@pytest.mark.parametrize("name, extra, words", CHECK, ids=[c[0] for c in CHECK])
def test_check_flags_refused(folders, capsys, name, extra, words):
    refused(["check", "--scene", str(folders["blender"]), *extra], capsys, words)


def test_check_of_a_synthetic_scene_refuses_calibration_flags(capsys):
    refused(["check", "--scene", "object", "--size", "24", "--depth-scale", "1000"], capsys,
            "apply to dataset folders")


OUTPUTS = [
    ("save into a folder", lambda t: ["--save", str(t)], "is a folder"),
    ("save as jpg", lambda t: ["--save", str(t / "v.jpg")], "must end in .png"),
    ("ply as png", lambda t: ["--ply", str(t / "s.png")], "must end in .ply"),
    ("ply under a file", lambda t: [(t / "f").write_text("x"), "--ply", str(t / "f" / "s.ply")][1:],
     "is a file, not a folder"),
]


@pytest.mark.parametrize("name, extra, words", OUTPUTS, ids=[c[0] for c in OUTPUTS])
def test_output_paths_refused_before_any_work(tmp_path, capsys, reached, name, extra, words):
    refused([*OBJECT, *extra(tmp_path)], capsys, words)


# --------------------------------------------------------------------------- python -m depth


def three_channel_model(fixed: bool):
    shape = [1, 3, 24, 24] if fixed else ["N", 3, "H", "W"]
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, shape)
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, shape if fixed else None)
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "rgb", [x], [y])
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


@pytest.fixture
def frames_dir(tmp_path, room):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i, f in enumerate(room.train[:2]):
        skio.imsave(folder / f"f{i}.png", (f.rgb * 255).astype(np.uint8), check_contrast=False)
    return folder


@pytest.mark.parametrize("fixed", [True, False], ids=["fixed shape", "symbolic shape"])
def test_depth_model_returning_three_channels_is_refused(tmp_path, frames_dir, capsys, fixed):
    model = tmp_path / "rgb.onnx"
    onnx.save(three_channel_model(fixed), model)
    before = digest(frames_dir)
    code = depth_main(["--model", str(model), "--input", str(frames_dir), "--output",
                       str(tmp_path / "out"), "--kind", "metric", "--no-progress"])
    err = capsys.readouterr().err
    words = "has no single-channel axis" if fixed else "returned shape (2, 3, 24, 24)"
    assert code == 2 and "Traceback" not in err and words in err
    assert digest(frames_dir) == before and not any((tmp_path / "out").glob("*.png"))


@pytest.mark.parametrize("out", ["same", "inside"])
def test_depth_output_in_the_input_is_refused(tmp_path, frames_dir, capsys, out):
    model = tmp_path / "rgb.onnx"
    onnx.save(three_channel_model(True), model)
    before = digest(frames_dir)
    target = frames_dir if out == "same" else frames_dir / "depth"
    code = depth_main(["--model", str(model), "--input", str(frames_dir), "--output",
                       str(target), "--kind", "metric", "--no-progress"])
    assert code == 2 and "Traceback" not in capsys.readouterr().err
    assert digest(frames_dir) == before


# --------------------------------------------------------------------------- frames (library)


def frame(**change):
    rgb = np.full((4, 5, 3), 0.5, np.float32)
    depth = np.ones((4, 5), np.float32)
    from vbgs.render.camera import Camera

    cam = Camera(4.0, 4.0, 2.5, 2.0, 5, 4, np.eye(4))
    cam = cam._replace(**{k: v for k, v in change.items() if k in cam._fields})
    return Frame(change.get("rgb", rgb), change.get("depth", depth), cam)


def pose_with(value_at):
    pose = np.eye(4)
    pose[value_at] = np.nan
    return pose


FRAMES = [
    ("rgb float64", frame(rgb=np.full((4, 5, 3), 0.5)), "dtype float64, expected float32"),
    ("rgb uint8", frame(rgb=np.full((4, 5, 3), 128, np.uint8)), "dtype uint8"),
    ("rgb 0..255 floats", frame(rgb=np.full((4, 5, 3), 128, np.float32)),
     "divide 8-bit images by 255"),
    ("rgb NaN", frame(rgb=np.full((4, 5, 3), np.nan, np.float32)), "NaN/inf values"),
    ("rgb transposed", frame(rgb=np.zeros((5, 4, 3), np.float32)), "rgb has shape (5, 4, 3)"),
    ("rgb grey", frame(rgb=np.zeros((4, 5), np.float32)), "rgb has shape (4, 5)"),
    ("depth negative", frame(depth=-np.ones((4, 5), np.float32)), "NaN, inf or negative"),
    ("depth NaN", frame(depth=np.full((4, 5), np.nan, np.float32)), "NaN, inf or negative"),
    ("depth inf", frame(depth=np.full((4, 5), np.inf, np.float32)), "NaN, inf or negative"),
    ("depth float64", frame(depth=np.ones((4, 5))), "depth has dtype float64"),
    ("depth 3 channels", frame(depth=np.ones((4, 5, 3), np.float32)), "single-channel"),
    ("depth transposed", frame(depth=np.ones((5, 4), np.float32)), "depth has shape (5, 4)"),
    ("pose NaN", frame(pose=pose_with((0, 3))), "NaN/inf entries"),
    ("pose 3x4", frame(pose=np.eye(4)[:3]), "[4, 4] matrix"),
    ("pose scaled", frame(pose=np.diag([2.0, 2, 2, 1])), "(scaled)"),
    ("pose reflected", frame(pose=np.diag([1.0, 1, -1, 1])), "determinant -1"),
    ("fx 0", frame(fx=0.0), "focal lengths must be positive"),
    ("fy negative", frame(fy=-4.0), "focal lengths must be positive"),
    ("fx NaN", frame(fx=float("nan")), "focal lengths must be positive"),
]


@pytest.mark.parametrize("name, bad, words", FRAMES, ids=[c[0] for c in FRAMES])
def test_bad_frames_refused_by_the_library(name, bad, words):
    with pytest.raises(ValueError, match=None) as err:
        validate_frame(bad, "frame")
    assert words in str(err.value)


def test_a_frame_without_depth_is_refused():
    with pytest.raises(ValueError, match="depth is 0 .missing. at every pixel"):
        require_some_depth(frame(depth=np.zeros((4, 5), np.float32)))


# --------------------------------------------------------------------------- EXIF, 1 frame


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
@pytest.mark.parametrize("orientation, shape, white", [
    (1, (10, 20), (slice(None), slice(0, 4))),
    (3, (10, 20), (slice(None), slice(16, 20))),
    (6, (20, 10), (slice(0, 4), slice(None))),
    (8, (20, 10), (slice(16, 20), slice(None))),
])
def test_exif_orientation_is_honoured(tmp_path, suffix, orientation, shape, white):
    """A 10x20 picture whose left band is white, stored with each EXIF orientation: read
    upright, the band is where a viewer shows it."""
    pixels = np.zeros((10, 20, 3), np.uint8)
    pixels[:, :5] = 255
    image = Image.fromarray(pixels)
    exif = image.getexif()
    exif[0x0112] = orientation
    path = tmp_path / f"photo{suffix}"
    image.save(path, exif=exif)
    rgb = read_rgb(path)
    assert rgb.shape[:2] == shape
    assert rgb[white].mean() > 0.9 and rgb.mean() < 0.5


class StopLearner:
    """Stands in for a learner: passes its check, stops when built (after the scene's
    warnings, before any compilation)."""

    @staticmethod
    def check(task):
        pass

    def __init__(self, task, scene):
        raise ValueError(f"stopped with {len(scene.train)} training frame(s)")


def test_one_frame_scene_is_warned_about_before_any_work(folders, tmp_path, capsys,
                                                         monkeypatch):
    monkeypatch.setitem(scene_task.LEARNERS, "vbgs", StopLearner)
    folder = copy(folders, "blender", tmp_path)
    edit_json(folder / "transforms_train.json", lambda m: m.update(frames=m["frames"][:1]))
    refused(["fit-scene", "--scene", str(folder), *FIT], capsys, "stopped with 1 training")
    code = main(["fit-scene", "--scene", str(folder), *FIT])
    assert code == 2 and "has one training frame" in capsys.readouterr().err


def test_fit_scene_warns_on_views_that_disagree_before_any_work(folders, tmp_path, capsys,
                                                                monkeypatch):
    """Consistency is a warning (views may differ for reasons the doctor cannot see); the
    scene the learner gets carries where its camera and depth scale came from."""
    monkeypatch.setitem(scene_task.LEARNERS, "vbgs", StopLearner)
    folder = copy(folders, "blender", tmp_path)
    poses_everywhere(np.linalg.inv)(folder)
    refused(["fit-scene", "--scene", str(folder), *FIT, "--depth-scale", "1000"], capsys,
            "stopped with 10 training frame(s)")
    code = main(["fit-scene", "--scene", str(folder), *FIT])
    err = capsys.readouterr().err
    assert code == 2 and "warning: consistency: only" in err and "world-to-camera" in err


def test_what_the_learner_gets_says_where_its_camera_came_from(folders, monkeypatch):
    seen = {}

    class Keep(StopLearner):
        def __init__(self, task, scene):
            seen.update(scene.record)
            super().__init__(task, scene)

    monkeypatch.setitem(scene_task.LEARNERS, "vbgs", Keep)
    assert main(["fit-scene", "--scene", str(folders["replica"]), *FIT, "--depth-scale",
                 "6553.5"]) == 2
    assert seen["format"] == "replica" and seen["depth_scale_from"] == "--depth-scale"
    assert seen["intrinsics_from"].endswith("cam_params.json")


@pytest.mark.slow
def test_one_frame_scene_runs_with_a_warning_and_says_what_ran(folders, tmp_path, capsys):
    folder = copy(folders, "blender", tmp_path)
    edit_json(folder / "transforms_train.json", lambda m: m.update(frames=m["frames"][:1]))
    code = main(["fit-scene", "--scene", str(folder), "--size", "16", "--components", "30",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and "one training frame" in err and "Traceback" not in err
    record = json.loads(out.strip().splitlines()[-1])
    assert record["frames"] == 1 and record["frames_asked"] == 60
