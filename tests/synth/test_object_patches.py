"""Printed patches on the standard objects: on the surface, at the printed pitch, facing out, apart."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.patterns import session_pattern
from handcap.synth.object_patches import LIFT, PATCHED, object_patch_grids, patch_coords
from handcap.synth.objects import make_object

PITCH = 0.005


@pytest.mark.parametrize("kind", PATCHED)
def test_patches_lie_on_their_object_at_the_printed_pitch_facing_out(kind):
    obj = make_object(kind)
    patches = [p for p in session_pattern((), (kind,)).patches if p.owner == kind]
    grids = object_patch_grids(obj, patches, PITCH)
    assert len(grids) == len(patches) > 0
    everything = []
    for patch, grid in zip(patches, grids):
        rows, cols = patch_coords(patch)
        assert grid.shape == (len(rows), len(cols), 3)
        # On the surface (the object's own signed distance, not its mesh), LIFT over it.
        np.testing.assert_allclose(obj.signed_distance(grid), LIFT, atol=1e-9)
        # The printed corners one square apart along rows and along columns: the printed pitch (flat faces), within
        # 1 % on the curved ones (a chord of the printed width around the cylinder, LIFT over its radius; on the
        # sphere the squares stretch across a little).
        r, c = np.isin(rows, np.arange(patch.rows + 1)), np.isin(cols, np.arange(patch.cols + 1))
        corners = grid[r][:, c]
        down = np.linalg.norm(np.diff(corners, axis=0), axis=-1)
        across = np.linalg.norm(np.diff(corners, axis=1), axis=-1)
        tolerance = 1e-9 if kind == "cuboid" else 0.01
        np.testing.assert_allclose(down, PITCH, rtol=tolerance)
        np.testing.assert_allclose(across, PITCH, rtol=tolerance)
        # Row x column points out of the object: the renderer reads the glyphs the right way round from outside.
        normal = np.cross(corners[1:, :-1] - corners[:-1, :-1], corners[:-1, 1:] - corners[:-1, :-1])
        centre = 0.25 * (corners[1:, 1:] + corners[:-1, :-1] + corners[1:, :-1] + corners[:-1, 1:])
        eps = 1e-5
        outward = np.stack([obj.signed_distance(centre + eps * e) - obj.signed_distance(centre - eps * e)
                            for e in np.eye(3)], axis=-1)
        assert (np.einsum("...i,...i->...", normal, outward) > 0).all()
        everything.append(grid.reshape(-1, 3))
    # No two patches overlap: every sample of a patch is over a square's side from every other patch's.
    for a in range(len(everything)):
        for b in range(a + 1, len(everything)):
            gap = np.linalg.norm(everything[a][:, None] - everything[b][None], axis=-1).min()
            assert gap > PITCH


def test_the_cube_and_patches_that_do_not_fit_are_refused():
    with pytest.raises(HandcapError, match="not on a cube2x2"):
        object_patch_grids(make_object("cube2x2"), [], PITCH)
    cuboid = make_object("cuboid")
    faces = [p for p in session_pattern((), ("cuboid",)).patches if p.owner == "cuboid"]
    with pytest.raises(HandcapError, match="larger than the cuboid's face"):
        object_patch_grids(cuboid, faces, 0.02)  # 4 x 4 squares of 2 cm on a 5 cm face
    sphere = [p for p in session_pattern((), ("sphere",)).patches if p.owner == "sphere"]
    with pytest.raises(HandcapError, match="has no face 'xp'"):
        object_patch_grids(make_object("sphere"), faces[:1], PITCH)
    with pytest.raises(HandcapError, match="does not fit on a cap"):
        object_patch_grids(make_object("sphere", scale=0.2), sphere, PITCH)


def test_the_cubes_facelet_patches_lie_where_its_tracker_looks_for_them():
    from handcap.objects import load_articulated
    from handcap.objects.cube import HOME
    from handcap.synth.object_patches import cube_patch_grids

    patches = [p for p in session_pattern((), ("cube2x2",)).patches if p.owner == "cube2x2"]
    grids, cubies = cube_patch_grids(patches, PITCH)
    cube = load_articulated("cube2x2-patches")  # the shipped description track-object --articulated reads
    home = {n: (k, m) for k, part in enumerate(cube.parts) for n, m in zip(part.marker_names, part.markers)}
    assert len(grids) == 24
    for patch, grid, cubie in zip(patches, grids, cubies):
        rows, cols = patch_coords(patch)
        for (r, c), name in zip(patch.vertices(), patch.corner_names()):
            part, spot = home[name]
            assert part == cubie and (np.sign(spot) == HOME[cubie]).all()
            np.testing.assert_allclose(grid[np.flatnonzero(rows == r)[0], np.flatnonzero(cols == c)[0]], spot,
                                       atol=1e-6)  # the description is written to the micrometre
        # Flat on its cubie's outer face, row x column pointing out of the cube.
        face = np.argmax(np.abs(grid).min(axis=(0, 1)))
        assert np.allclose(np.abs(grid[..., face]), 0.028)
        normal = np.cross(grid[1, 0] - grid[0, 0], grid[0, 1] - grid[0, 0])
        assert normal[face] * np.sign(grid[0, 0, face]) > 0
    with pytest.raises(HandcapError, match="not a facelet"):
        cube_patch_grids([p for p in session_pattern((), ("cuboid",)).patches if p.owner == "cuboid"], PITCH)
