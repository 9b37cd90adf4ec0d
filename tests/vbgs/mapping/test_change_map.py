"""Colour judged against the map as a whole (``evidence.recolour_reference="map"``,
vbgs.mapping.change): a repainted surface is forgotten and an edge component whose side
rays land on the neighbouring face is not blamed (a static stream forgets nothing:
``test_change.test_judged_by_colour_a_static_stream_forgets_nothing_to_the_bit``)."""

import jax.numpy as jnp
import numpy as np

from vbgs.data.synthetic import make_scene
from vbgs.mapping import change
from vbgs.render.camera import Camera
from vbgs.render.opacity import frame_evidence
from vbgs.render.raster import rasterize
from vbgs.render.splats import Splats

from tests.vbgs.mapping.test_change import FRAMES, SIZE, config, repainted, stream

RED, BLUE, GREEN = (0.9, 0.1, 0.1), (0.1, 0.1, 0.9), (0.1, 0.9, 0.1)
SIDE, FOCAL, DEPTH = 32, 32.0, 2.0


def faces(left, right, edge=None):
    """Two faces meeting at the image's middle column, at camera depth 2, tiled by
    splats of ``left`` and ``right`` colour, and an ``edge`` component (red, thin across
    the edge, its mean two pixels right of it: its rays read the right face) when given."""
    step = 0.125  # world units between splats, 2 px at depth 2
    xs = np.arange(-1.0 + step / 2, 1.0, step)
    grid = np.array([(x, y, DEPTH) for x in xs for y in xs], np.float32)
    colours = np.array([left if x < 0 else right for x, _, _ in grid], np.float32)
    covs = np.tile(np.diag([(step / 2)**2, (step / 2)**2, 1e-4]).astype(np.float32), (len(grid), 1, 1))
    if edge is not None:
        grid = np.vstack([grid, [[0.15, 0.0, DEPTH]]]).astype(np.float32)
        covs = np.vstack([covs, np.diag([0.02**2, 0.25**2, 0.01**2])[None]]).astype(np.float32)
        colours = np.vstack([colours, [edge]]).astype(np.float32)
    return Splats(jnp.asarray(grid), jnp.asarray(covs), jnp.asarray(colours),
                  jnp.full(len(grid), 0.99, jnp.float32))


def camera():
    c = SIDE / 2.0
    return Camera(FOCAL, FOCAL, c, c, SIDE, SIDE, jnp.eye(4, dtype=jnp.float32))


def evidence(map_splats, frame_rgb, sigmas=2.0):
    cam = camera()
    depth = np.full((SIDE, SIDE), DEPTH, np.float32)
    blame = change.blame(map_splats, cam, frame_rgb, None, sigmas, 0.05, 0.3)
    return frame_evidence(map_splats.means, map_splats.covs, cam, depth, rgb=frame_rgb,
                          blame=blame)


def test_an_edge_component_seen_from_one_side_is_not_blamed():
    """The edge component's rays land on the blue face, a colour far from its own red (the
    history and its own posterior both disagree), but the map draws that face blue: the
    map explains the pixels and the edge is not blamed. Where the blue face is repainted
    green the map no longer explains them: both the face's components and the edge's are
    blamed."""
    world = faces(RED, BLUE, edge=RED)
    seen = np.asarray(rasterize(faces(RED, BLUE), camera()).rgb)  # the world as it is
    frame = evidence(world, seen)
    edge = -1
    assert int(frame.n_shown[edge]) == 5  # every ray hits it, on the blue face
    own = np.asarray(RED)
    assert float(((np.asarray(frame.shown[edge]) - own) ** 2).sum()) > 1.0  # far from red
    assert int(frame.blamed[edge]) == 0
    assert int(np.asarray(frame.blamed).max()) == 0  # nothing blamed where nothing changed

    repaint = np.asarray(rasterize(faces(RED, GREEN), camera()).rgb)
    frame = evidence(world, repaint)
    blamed = np.asarray(frame.blamed)
    right = np.asarray(world.means)[:-1, 0] > 0.2  # the repainted face's inner splats
    left = np.asarray(world.means)[:-1, 0] < -0.2
    assert int(blamed[edge]) >= change.MIN_COLOUR_HITS
    assert np.mean(blamed[:-1][right] >= change.MIN_COLOUR_HITS) > 0.8
    assert int(blamed[:-1][left].max()) == 0


def test_against_the_map_a_repainted_surface_is_forgotten():
    """The object repainted after its first lap (the same depth): judged against the map,
    its components are forgotten (no gate); by depth's evidence alone none is, nor behind
    the default gate (nothing moved)."""
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    lap = FRAMES // 2
    frames = scene.train[:lap] + [repainted(f) for f in scene.train[lap:]]
    background = (np.asarray(scene.background) + 0.5) % 1.0
    on = stream(frames, config(recolour=2.0, reference="map", gate=0.0), background)
    off = stream(frames, config(recolour=0.0), background)
    assert stream(frames, config(recolour=2.0, reference="map"), background).n_forgotten == 0
    assert off.n_forgotten == 0
    assert on.n_forgotten > 300, on.n_forgotten  # measured 572 of about 4000
