"""ManoHand: reading MANO-layout pickles without chumpy, against an independent MANO forward.

MANO's files are licensed and never shipped, so these tests write files with the
same keys, types and shapes: ``shapedirs`` is a chumpy ``Ch`` object,
``J_regressor`` a ``scipy.sparse.csc.csc_matrix``, arrays use the Python-2-era
``numpy.core.multiarray`` path. The geometry is OpenHand's mesh clustered to
MANO's 778 vertices, so joints and frames make anatomical sense.
"""

import copyreg
import re
import os
import pickle
import struct
import sys
import types
import weakref

import numpy as np
import pytest
import scipy.sparse
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.hand import ManoHand, OpenHand, load_hand_model
from handcap.hand.anatomy import joint_frames

# MANO's fingertip vertex ids (thumb, index, middle, ring, pinky) and its tree,
# typed here independently of handcap.hand.mano.
TIP_IDS = [745, 317, 444, 556, 673]
TIP_JOINTS = [15, 3, 6, 12, 9]
KINTREE = np.array([[4294967295, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14], list(range(16))],
                   dtype=np.int64)
X_MIRROR = np.array([-1.0, 1.0, 1.0])


# -- a MANO-layout model -----------------------------------------------------------------
def make_model(seed=0):
    """Arrays of a plausible right-hand MANO model (dense, plain numpy)."""
    hand = OpenHand("right")
    verts, faces = hand.template_vertices, hand.faces
    _, joints, tips = hand.rest(np.zeros(10))
    # Farthest-point sample 778 vertices, starting from the ones nearest the five tips.
    chosen = list(cKDTree(verts).query(tips)[1])
    dist = np.min(np.linalg.norm(verts[:, None] - verts[chosen][None], axis=2), axis=1)
    while len(chosen) < 778:
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(verts - verts[i], axis=1))
    # Put the tip vertices at MANO's tip ids.
    order = [c for c in chosen[5:]]
    for vid, src in sorted(zip(TIP_IDS, chosen[:5])):
        order.insert(vid, src)
    order = np.array(order)
    v_template = verts[order]
    # Faces: cluster OpenHand's triangles onto the chosen vertices, drop degenerate ones.
    label = cKDTree(v_template).query(verts)[1]
    f = label[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    f = f[np.sort(first)][:1538].astype(np.uint32)
    weights = hand.weights[order].copy()
    # Tip vertices belong wholly to their distal segment (handcap moves tips rigidly with it).
    weights[TIP_IDS] = np.eye(16)[TIP_JOINTS]
    weights /= weights.sum(axis=1, keepdims=True)
    # Joint regressor: the mean of the 8 vertices nearest each OpenHand joint.
    regressor = np.zeros((16, 778))
    for j, near in enumerate(cKDTree(v_template).query(joints, k=8)[1]):
        regressor[j, near] = 1.0 / 8
    rng = np.random.default_rng(seed)
    centred = v_template - v_template.mean(axis=0)
    shapedirs = rng.normal(scale=2e-3, size=(778, 3, 10))
    shapedirs[:, :, 0] = 0.03 * centred + rng.normal(scale=5e-4, size=(778, 3))  # size, as MANO's first
    posedirs = rng.normal(scale=1e-3, size=(778, 3, 135))
    posedirs[TIP_IDS] = 0.0
    components = np.linalg.qr(rng.normal(size=(45, 45)))[0]
    return {
        "v_template": v_template, "f": f, "weights": weights, "J_regressor": regressor,
        "shapedirs": shapedirs, "posedirs": posedirs, "kintree_table": KINTREE.copy(),
        "J": regressor @ v_template, "hands_components": components,
        "hands_mean": rng.normal(scale=0.1, size=45), "hands_coeffs": rng.normal(size=(20, 45)),
        "bs_style": "lbs", "bs_type": "lrotmin",
    }


def left_of(model, *, shapedirs_error):
    """The left model as MANO made it: the right one mirrored in x (faces flipped)."""
    left = dict(model)
    left["v_template"] = model["v_template"] * X_MIRROR
    left["J"] = model["J"] * X_MIRROR
    left["f"] = model["f"][:, ::-1].copy()
    # MANO_LEFT.pkl left shapedirs[:, 0, :] unmirrored (smplx issue #48).
    left["shapedirs"] = model["shapedirs"] * (1.0 if shapedirs_error else X_MIRROR[:, None])
    return left


def fake_modules():
    """``chumpy``, ``chumpy.ch``, ``chumpy.ch_ops`` and ``scipy.sparse.csc`` stand-ins for pickling."""
    chumpy, ch, ch_ops, csc = (types.ModuleType(n) for n in
                               ("chumpy", "chumpy.ch", "chumpy.ch_ops", "scipy.sparse.csc"))

    class Ch:
        def __init__(self, x):
            self.x = np.asarray(x)
            self._parents = weakref.WeakKeyDictionary()
            self._cache = {"r": None, "drs": weakref.WeakKeyDictionary()}
            self._dirty_vars = set()
            self._itr = None
            self._depends_on_deps = True
            self._make_dense = False
            self._make_sparse = False

        def __getstate__(self):  # chumpy's: drop the unpicklable weak dictionaries
            result = dict(self.__dict__)
            del result["_parents"]
            del result["_cache"]
            return result

    class add(Ch):  # a chumpy expression: no array of its own
        def __init__(self, a, b):
            super().__init__(np.zeros(0))
            del self.x
            self.a, self.b = a, b

    class csc_matrix:
        """Pickles like Python 2's object.__reduce_ex__(0): copy_reg._reconstructor."""

        def __init__(self, dense):
            real = scipy.sparse.csc_array(dense)
            self.data, self.indices, self.indptr = real.data, real.indices, real.indptr
            self._shape, self.maxprint, self.format = dense.shape, 50, "csc"

        def __reduce_ex__(self, protocol):
            return copyreg._reconstructor, (type(self), object, None), dict(self.__dict__)

    for cls, module in ((Ch, ch), (add, ch_ops), (csc_matrix, csc)):
        cls.__module__, cls.__qualname__ = module.__name__, cls.__name__
        setattr(module, cls.__name__, cls)
    chumpy.ch, chumpy.ch_ops, chumpy.Ch = ch, ch_ops, Ch
    return {"chumpy": chumpy, "chumpy.ch": ch, "chumpy.ch_ops": ch_ops, "scipy.sparse.csc": csc}


def write_mano(path, model, *, old_numpy_paths=True, chumpy_expression=False):
    """Pickle ``model`` (protocol 2) the way MANO's files are laid out."""
    modules = fake_modules()
    real_csc = sys.modules.get("scipy.sparse.csc")
    with pytest.MonkeyPatch.context() as mp:
        for name, module in modules.items():
            mp.setitem(sys.modules, name, module)
        Ch, csc = modules["chumpy.ch"].Ch, modules["scipy.sparse.csc"].csc_matrix
        data = dict(model)
        data["shapedirs"] = Ch(model["shapedirs"])
        if chumpy_expression:
            data["shapedirs"] = modules["chumpy.ch_ops"].add(Ch(model["shapedirs"]), Ch(model["shapedirs"]))
        if "J_regressor" in model:
            data["J_regressor"] = csc(model["J_regressor"])
        raw = pickle.dumps(data, protocol=2)
    # The loader must work with neither chumpy nor the fakes importable.
    assert "chumpy" not in sys.modules and "chumpy.ch" not in sys.modules
    assert sys.modules.get("scipy.sparse.csc") is real_csc
    if old_numpy_paths:  # as written by numpy 1.x (the real files)
        raw = raw.replace(b"cnumpy._core.multiarray\n", b"cnumpy.core.multiarray\n")
        assert b"numpy._core" not in raw
    path.write_bytes(raw)
    return path


@pytest.fixture(scope="module")
def model():
    return make_model()


@pytest.fixture(scope="module")
def mano_dir(tmp_path_factory, model):
    folder = tmp_path_factory.mktemp("mano")
    write_mano(folder / "MANO_RIGHT.pkl", model)
    write_mano(folder / "MANO_LEFT.pkl", left_of(model, shapedirs_error=True), old_numpy_paths=False)
    return folder


# -- an independent MANO forward -----------------------------------------------------
def mano_reference(model, betas, global_orient, hand_pose, transl):
    """MANO (Romero et al. 2017) with flat_hand_mean=True, one frame, plain numpy.

    Returns vertices (778, 3) and joints (21, 3): 16 posed joints, then the tip vertices.
    """
    v_shaped = model["v_template"] + np.einsum("vck,k->vc", model["shapedirs"], betas)
    rest = model["J_regressor"] @ v_shaped
    rot = Rotation.from_rotvec(np.concatenate([global_orient, hand_pose]).reshape(16, 3)).as_matrix()
    lrotmin = (rot[1:] - np.eye(3)).ravel()
    v_posed = v_shaped + np.einsum("vcp,p->vc", model["posedirs"], lrotmin)
    column = {jid: i for i, jid in enumerate(model["kintree_table"][1])}
    world = np.zeros((16, 4, 4))
    for i in range(16):
        local = np.eye(4)
        local[:3, :3] = rot[i]
        if i == 0:
            local[:3, 3] = rest[0]
            world[0] = local
        else:
            parent = column[model["kintree_table"][0, i]]
            local[:3, 3] = rest[i] - rest[parent]
            world[i] = world[parent] @ local
    skin = world.copy()
    skin[:, :3, 3] -= np.einsum("jab,jb->ja", world[:, :3, :3], rest)
    blend = np.einsum("vj,jab->vab", model["weights"], skin)
    verts = np.einsum("vab,vb->va", blend[:, :3, :3], v_posed) + blend[:, :3, 3] + transl
    joints = np.concatenate([world[:, :3, 3] + transl, verts[TIP_IDS]])
    return verts, joints


def random_inputs(seed, n):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=10), rng.normal(scale=0.8, size=(n, 3)), rng.normal(scale=0.5, size=(n, 45)),
            rng.normal(scale=0.2, size=(n, 3)))


# -- loading ----------------------------------------------------------------------------
def test_loads_the_arrays_of_the_file_without_chumpy(mano_dir, model):
    hand = ManoHand.load(mano_dir / "MANO_RIGHT.pkl")
    assert "chumpy" not in sys.modules
    assert hand.name == "mano" and hand.side == "right" and hand.n_vertices == 778
    np.testing.assert_array_equal(hand.template_vertices, model["v_template"])
    np.testing.assert_array_equal(hand.faces, model["f"])
    np.testing.assert_array_equal(hand.shapedirs, model["shapedirs"])
    np.testing.assert_allclose(hand.joint_regressor, model["J_regressor"], atol=1e-15)
    np.testing.assert_array_equal(hand.weights, model["weights"])
    np.testing.assert_array_equal(hand.posedirs, model["posedirs"])
    expect = joint_frames(model["J_regressor"] @ model["v_template"], model["v_template"][TIP_IDS], True)
    np.testing.assert_allclose(hand.frames, expect, atol=1e-12)


def test_folder_and_file_give_the_same_model(mano_dir):
    a, b = ManoHand.load(mano_dir), ManoHand.load(mano_dir / "MANO_RIGHT.pkl", side="right")
    np.testing.assert_array_equal(a.template_vertices, b.template_vertices)
    assert ManoHand.load(mano_dir, side="left").side == "left"


def test_reads_a_plain_protocol_5_file(tmp_path, model):
    # A file re-saved with numpy 2 and no chumpy: plain arrays, dense J_regressor.
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(model, protocol=5))
    np.testing.assert_array_equal(ManoHand.load(path).shapedirs, model["shapedirs"])


def test_reads_python2_str_array_data(tmp_path):
    # Python 2 pickles array bytes as str (SHORT_BINSTRING/BINSTRING), read back as latin-1 text.
    # Hand-assembled: {'x': array of shape (2, 3)} as Python 2 and numpy 1 wrote it.
    from handcap.hand.mano_pickle import read_pickle as _read_pickle

    def string(b):
        return (b"U" + bytes([len(b)]) if len(b) < 256 else b"T" + struct.pack("<i", len(b))) + b

    array = np.arange(6.0).reshape(2, 3)
    raw = (b"\x80\x02}" + string(b"x")
           + b"cnumpy.core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85" + string(b"b") + b"\x87R"
           + b"(K\x01K\x02K\x03\x86cnumpy\ndtype\n" + string(b"f8") + b"K\x00K\x01\x87R"
           + b"(K\x03" + string(b"<") + b"NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb"
           + b"\x89" + string(array.tobytes()) + b"tbs.")
    path = tmp_path / "py2.pkl"
    path.write_bytes(raw)
    np.testing.assert_array_equal(_read_pickle(path)["x"], array)


def test_rest_is_mano_shape_blend_and_joint_regression(mano_dir, model):
    hand = ManoHand.load(mano_dir)
    betas = np.random.default_rng(3).normal(size=(4, 10))
    verts, joints, tips = hand.rest(betas)
    expect = model["v_template"] + np.einsum("vck,tk->tvc", model["shapedirs"], betas)
    np.testing.assert_allclose(verts, expect, atol=1e-12)
    np.testing.assert_allclose(joints, np.einsum("jv,tvc->tjc", model["J_regressor"], expect), atol=1e-12)
    np.testing.assert_allclose(tips, expect[:, TIP_IDS], atol=1e-12)


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("side", ["right", "left"])
def test_forward_matches_an_independent_mano(mano_dir, model, side, seed):
    hand = ManoHand.load(mano_dir, side)
    # The left file has smplx #48's error; the loader's repaired model is MANO's left hand.
    reference = model if side == "right" else left_of(model, shapedirs_error=False)
    betas, orient, pose, transl = random_inputs(seed, 4)
    out = hand.forward(betas, orient, pose, transl)
    for t in range(4):
        verts, joints = mano_reference(reference, betas, orient[t], pose[t], transl[t])
        np.testing.assert_allclose(out.vertices[t], verts, atol=1e-12)
        np.testing.assert_allclose(out.joints[t], joints, atol=1e-12)


def test_torch_forward_matches_the_reference_and_is_differentiable(mano_dir, model):
    hand = ManoHand.load(mano_dir)
    betas, orient, pose, transl = random_inputs(7, 3)
    t = lambda a: torch.tensor(a, dtype=torch.float64, requires_grad=True)  # noqa: E731
    tb, tp = t(betas), t(pose)
    out = hand.forward(tb, t(orient), tp, t(transl))
    for i in range(3):
        verts, joints = mano_reference(model, betas, orient[i], pose[i], transl[i])
        np.testing.assert_allclose(out.vertices[i].detach().numpy(), verts, atol=1e-10)
        np.testing.assert_allclose(out.joints[i].detach().numpy(), joints, atol=1e-10)
    out.vertices.sum().backward()
    assert torch.isfinite(tb.grad).all() and tp.grad.abs().sum() > 0


def test_pose_blend_shapes_are_used(mano_dir, model):
    # Without posedirs the same pose gives a visibly different mesh: the correctives matter.
    hand = ManoHand.load(mano_dir)
    pose = np.random.default_rng(4).normal(scale=0.5, size=45)
    flat = dict(model, posedirs=np.zeros_like(model["posedirs"]))
    verts, _ = mano_reference(flat, np.zeros(10), np.zeros(3), pose, np.zeros(3))
    assert np.abs(hand.forward(hand_pose=pose).vertices - verts).max() > 1e-3


def test_attached_markers_on_mano_follow_its_pose_blend_shapes(mano_dir):
    # The solver's marker model takes MANO's correctives path; it must equal the skinned mesh.
    from handcap.hand.attachment import MarkerAttachment
    from handcap.layouts import load_layout
    from handcap.solve.markers import MarkerModel
    hand = ManoHand.load(mano_dir)
    rng = np.random.default_rng(6)
    att = MarkerAttachment.from_layout(load_layout("glove-13"), hand, rng.normal(size=10) * 0.5)
    model = MarkerModel(hand, att)
    assert model.has_correctives
    phi = rng.normal(scale=0.3, size=(3, 27))
    rot = Rotation.from_rotvec(rng.normal(size=(3, 3))).as_matrix()
    transl = rng.normal(size=(3, 3))
    out = hand.forward(att.betas, Rotation.from_matrix(rot).as_rotvec(), phi=phi, transl=transl)
    np.testing.assert_allclose(model.positions(transl, rot, phi), att.positions(out.vertices, hand.faces),
                               atol=1e-12)


def test_zero_pose_is_the_template_not_the_hands_mean(mano_dir, model):
    out = ManoHand.load(mano_dir).forward()
    np.testing.assert_allclose(out.vertices, model["v_template"], atol=1e-15)


def test_chumpy_ch_state_holds_the_keys_chumpy_pickles():
    # The stand-in Ch pickles what chumpy's __getstate__ gives: __dict__ less _parents and _cache.
    state = fake_modules()["chumpy.ch"].Ch(np.zeros(2)).__getstate__()
    assert set(state) == {"x", "_dirty_vars", "_itr", "_depends_on_deps", "_make_dense", "_make_sparse"}


# -- the left model ---------------------------------------------------------------------
@pytest.mark.parametrize("with_right", [True, False])
@pytest.mark.parametrize("shapedirs_error", [True, False])
def test_left_shapedirs_are_repaired_when_needed(tmp_path, model, with_right, shapedirs_error):
    if with_right:
        write_mano(tmp_path / "MANO_RIGHT.pkl", model)
    write_mano(tmp_path / "MANO_LEFT.pkl", left_of(model, shapedirs_error=shapedirs_error))
    left = ManoHand.load(tmp_path, side="left")
    assert left.fixed_left_shapedirs == shapedirs_error
    np.testing.assert_array_equal(left.shapedirs, model["shapedirs"] * X_MIRROR[:, None])
    # Equal betas now give mirror-image hands.
    betas = np.random.default_rng(5).normal(size=10) * 2
    right_verts = mano_reference(model, betas, np.zeros(3), np.zeros(45), np.zeros(3))[0]
    np.testing.assert_allclose(left.rest(betas)[0], right_verts * X_MIRROR, atol=1e-12)


def test_left_repair_by_comparison_does_not_need_a_size_component(tmp_path, model):
    # With the right file at hand, smplx's test decides even when beta 0 is not a size change.
    odd = dict(model, shapedirs=np.random.default_rng(6).normal(scale=2e-3, size=(778, 3, 10)))
    write_mano(tmp_path / "MANO_RIGHT.pkl", odd)
    write_mano(tmp_path / "MANO_LEFT.pkl", left_of(odd, shapedirs_error=True))
    assert ManoHand.load(tmp_path / "MANO_LEFT.pkl", side="left").fixed_left_shapedirs


def test_left_alone_undecidable_asks_for_help(tmp_path, model):
    odd = dict(model, shapedirs=np.random.default_rng(6).normal(scale=2e-3, size=(778, 3, 10)))
    write_mano(tmp_path / "MANO_LEFT.pkl", left_of(odd, shapedirs_error=True))
    with pytest.raises(HandcapError, match="cannot tell.*fix_left_shapedirs"):
        ManoHand.load(tmp_path, side="left")
    forced = ManoHand.load(tmp_path, side="left", fix_left_shapedirs=True)
    np.testing.assert_array_equal(forced.shapedirs, odd["shapedirs"] * X_MIRROR[:, None])
    kept = ManoHand.load(tmp_path, side="left", fix_left_shapedirs=False)
    np.testing.assert_array_equal(kept.shapedirs, odd["shapedirs"])


def test_left_model_frames_are_mirror_images(mano_dir):
    left, right = ManoHand.load(mano_dir, side="left"), ManoHand.load(mano_dir)
    np.testing.assert_allclose(left.frames, right.frames * X_MIRROR[:, None], atol=1e-12)
    assert (np.linalg.det(left.frames) < 0).all() and (np.linalg.det(right.frames) > 0).all()


# -- choosing a model -------------------------------------------------------------------
def test_load_hand_model_specs(mano_dir, monkeypatch):
    assert isinstance(load_hand_model(), OpenHand)
    assert load_hand_model("openhand", "left").side == "left"
    hand = load_hand_model(f"mano:{mano_dir}", "left")
    assert isinstance(hand, ManoHand) and hand.side == "left"
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(mano_dir))
    assert isinstance(load_hand_model("mano"), ManoHand)
    monkeypatch.delenv("HANDCAP_MANO_DIR")
    with pytest.raises(HandcapError, match="HANDCAP_MANO_DIR.*not set"):
        load_hand_model("mano")
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(mano_dir / "nowhere"))
    with pytest.raises(HandcapError, match="not a folder"):
        load_hand_model("mano")
    with pytest.raises(HandcapError, match="unknown hand model 'smplx'.*openhand, mano"):
        load_hand_model("smplx")
    with pytest.raises(HandcapError, match="needs a folder"):
        load_hand_model("mano:")
    with pytest.raises(HandcapError, match="side must be"):
        load_hand_model("openhand", "both")


# -- bad files ------------------------------------------------------------------------
def test_not_a_pickle(tmp_path):
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(HandcapError, match="not a readable MANO model pickle"):
        ManoHand.load(path)


def test_pickle_of_something_else(tmp_path):
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps([1, 2, 3], protocol=2))
    with pytest.raises(HandcapError, match="holds a list, not the dict"):
        ManoHand.load(path)


def test_missing_key(tmp_path, model):
    data = {k: v for k, v in model.items() if k != "J_regressor"}
    path = write_mano(tmp_path / "MANO_RIGHT.pkl", data)
    with pytest.raises(HandcapError, match="MANO_RIGHT.pkl has no 'J_regressor'"):
        ManoHand.load(path)


@pytest.mark.parametrize(("key", "value", "message"), [
    ("shapedirs", np.zeros((778, 3, 9)), r"shapedirs must have shape \(778, 3, 10\), got \(778, 3, 9\)"),
    ("v_template", np.zeros((777, 3)), r"v_template must have shape \(778, 3\)"),
    ("posedirs", np.zeros((778, 3, 135)) * np.nan, "posedirs has NaN"),
    ("f", np.full((10, 3), 778), "f must index the 778 vertices"),
    ("kintree_table", np.array([[0] * 16, list(range(16))]), "not MANO's hand tree"),
])
def test_wrong_arrays(tmp_path, model, key, value, message):
    path = write_mano(tmp_path / "MANO_RIGHT.pkl", dict(model, **{key: value}))
    with pytest.raises(HandcapError, match=message):
        ManoHand.load(path)


def test_weights_must_sum_to_one(tmp_path, model):
    path = write_mano(tmp_path / "MANO_RIGHT.pkl", dict(model, weights=model["weights"] * 2))
    with pytest.raises(HandcapError, match="weights of vertex 0 sum to 2"):
        ManoHand.load(path)


def test_chumpy_expression_is_refused_clearly(tmp_path, model):
    path = write_mano(tmp_path / "MANO_RIGHT.pkl", model, chumpy_expression=True)
    with pytest.raises(HandcapError, match=r"shapedirs is a chumpy expression \(chumpy.ch_ops.add\)"):
        ManoHand.load(path)


class _Exploit:
    def __init__(self, call, argument):
        self.call, self.argument = call, argument

    def __reduce__(self):
        return self.call, (self.argument,)


@pytest.mark.parametrize("call", [os.system, eval])
def test_malicious_pickle_is_refused_and_runs_nothing(tmp_path, model, call):
    marker = tmp_path / "pwned"
    command = f"touch {marker}" if call is os.system else f"open({str(marker)!r}, 'w').close()"
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(dict(model, bs_style=_Exploit(call, command)), protocol=2))
    with pytest.raises(HandcapError, match=r"refusing to load (posix|nt|builtins|__builtin__)\.(system|eval)"):
        ManoHand.load(path)
    assert not marker.exists()


def test_missing_files_and_wrong_side(tmp_path, mano_dir):
    with pytest.raises(HandcapError, match="no MANO_LEFT.pkl in"):
        ManoHand.load(tmp_path, side="left")
    with pytest.raises(HandcapError, match="does not exist"):
        ManoHand.load(tmp_path / "MANO_RIGHT.pkl")
    with pytest.raises(HandcapError, match="MANO_LEFT.pkl is the left hand but side='right'"):
        ManoHand.load(mano_dir / "MANO_LEFT.pkl")
    with pytest.raises(HandcapError, match="left hand only"):
        ManoHand.load(mano_dir, fix_left_shapedirs=True)


# -- from the command line (--hand-model, --mano-dir, HANDCAP_MANO_DIR) ---------------------------------------------
@pytest.fixture(scope="module")
def glove_takes(tmp_path_factory):
    """A calibration take and a take of one synthetic subject with the glove-13 layout, as .npz files."""
    from handcap.io import write_markers
    from handcap.synth.scene import SynthConfig, synthesize
    folder = tmp_path_factory.mktemp("takes")
    for name, motion, seed, frames in (("cal", "calibration", 31, 40), ("take", "open-close", 32, 20)):
        capture = synthesize(SynthConfig(layout="glove-13", motion=motion, frames=frames, seed=seed, subject_seed=4,
                                         ghost_rate=0), progress=False)
        write_markers(capture.markers, folder / f"{name}.npz")
    return folder


def run_cli(*argv):
    from handcap.cli import main
    return main([str(a) for a in argv])


def test_cli_calibrates_and_solves_with_mano(glove_takes, mano_dir, model, monkeypatch, capsys):
    from handcap.hand.attachment import MarkerAttachment
    from handcap.io import read_hand_motion
    monkeypatch.delenv("HANDCAP_MANO_DIR", raising=False)
    attachment, motion = glove_takes / "att.npz", glove_takes / "motion.npz"
    assert run_cli("calibrate-markers", glove_takes / "cal.npz", "--layout", "glove-13", "--hand-model", "mano",
                   "--mano-dir", mano_dir, "--out", attachment) == 0
    att = MarkerAttachment.load(attachment)
    assert att.model == "mano" and att.triangles.max() < len(model["f"])
    # Solving reads the model from the attachment, and its files from HANDCAP_MANO_DIR.
    assert run_cli("solve", glove_takes / "take.npz", "--attachment", attachment, "--out", motion) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--mano-dir DIR or set HANDCAP_MANO_DIR" in err[0]
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(mano_dir))
    assert run_cli("solve", glove_takes / "take.npz", "--attachment", attachment, "--out", motion) == 0
    solved = read_hand_motion(motion)
    assert solved.model == "mano"
    # The written joints and markers are MANO's (an independent forward) at the written parameters.
    for t in (0, solved.n_frames - 1):
        verts, joints = mano_reference(model, solved.betas, solved.global_orient[t], solved.hand_pose[t],
                                       solved.transl[t])
        np.testing.assert_allclose(solved.joints[t], joints, atol=1e-6)
        np.testing.assert_allclose(solved.marker_fit[t], att.positions(verts, model["f"].astype(np.int64)),
                                   atol=1e-6)


def test_cli_refuses_a_model_other_than_the_attachments(glove_takes, mano_dir, monkeypatch, capsys):
    monkeypatch.delenv("HANDCAP_MANO_DIR", raising=False)
    openhand = glove_takes / "att_openhand.npz"
    assert run_cli("calibrate-markers", glove_takes / "cal.npz", "--layout", "glove-13", "--out", openhand) == 0
    out = glove_takes / "m.npz"
    assert run_cli("solve", glove_takes / "take.npz", "--attachment", openhand, "--mano-dir", mano_dir,
                   "--out", out) == 2
    assert "made with the openhand hand model, not mano" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("options, message", [
    (["--hand-model", "mano", "--mano-dir", "{tmp}/nowhere"], r"MANO folder .*nowhere does not exist"),
    (["--mano-dir", "{tmp}"], "no MANO_RIGHT.pkl in"),
    (["--hand-model", "mano:{tmp}/nowhere"], "does not exist"),
    (["--hand-model", "mano"], "needs its files: give --mano-dir DIR or set HANDCAP_MANO_DIR"),
    (["--hand-model", "openhand", "--mano-dir", "{tmp}"], "--mano-dir goes with --hand-model mano"),
    (["--hand-model", "smplx"], "unknown hand model 'smplx'"),
])
def test_cli_missing_mano_files_are_one_line_errors(tmp_path, monkeypatch, capsys, options, message):
    monkeypatch.delenv("HANDCAP_MANO_DIR", raising=False)
    out = tmp_path / "betas.npz"
    argv = ["shape", "--lengths", "hand_length=190", "--out", out] + [o.format(tmp=tmp_path) for o in options]
    assert run_cli(*argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("handcap shape: error:")
    assert re.search(message, err[0]) and not out.exists()


def test_cli_shape_fits_the_chosen_model(tmp_path, mano_dir, monkeypatch):
    from handcap.solve import hand_measurements
    monkeypatch.delenv("HANDCAP_MANO_DIR", raising=False)
    for options, hand in ((["--hand-model", f"mano:{mano_dir}"], ManoHand.load(mano_dir)), ([], OpenHand())):
        out = tmp_path / f"betas{len(options)}.npz"
        assert run_cli("shape", "--lengths", "hand_length=195", "--out", out, *options) == 0
        betas = np.load(out)["betas"]
        # The length is met on the model that was asked for (MANO's shape space differs from OpenHand's).
        assert hand_measurements(hand, betas)["hand_length"] == pytest.approx(0.195, abs=0.001)


def test_cli_metrics_needs_the_motions_model_for_the_mesh(glove_takes, mano_dir, monkeypatch, capsys):
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(mano_dir))
    attachment, motion = glove_takes / "att2.npz", glove_takes / "motion2.npz"
    assert run_cli("calibrate-markers", glove_takes / "cal.npz", "--layout", "glove-13", "--hand-model", "mano",
                   "--out", attachment) == 0
    assert run_cli("solve", glove_takes / "take.npz", "--attachment", attachment, "--out", motion) == 0
    capsys.readouterr()
    leave_one_out = ["metrics", motion, "--markers", glove_takes / "take.npz", "--attachment", attachment,
                     "--leave-one-out"]
    assert run_cli(*leave_one_out, "--hand-model", "openhand") == 2
    assert "made with the mano hand model" in capsys.readouterr().err
    assert run_cli(*leave_one_out) == 0
    assert "leave" in capsys.readouterr().out.lower()


def test_hand_model_from_options_precedence(mano_dir, tmp_path, monkeypatch):
    from handcap.hand import hand_model_from_options
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(tmp_path / "elsewhere"))
    assert isinstance(hand_model_from_options(), OpenHand)
    # --mano-dir wins over the environment and implies the MANO model; the side is passed on.
    hand = hand_model_from_options(None, mano_dir, side="left")
    assert isinstance(hand, ManoHand) and hand.side == "left"
    # A recorded model is the default, and another choice is refused.
    assert isinstance(hand_model_from_options(recorded="openhand"), OpenHand)
    with pytest.raises(HandcapError, match="attachment.npz was made with the mano hand model, not openhand"):
        hand_model_from_options("openhand", recorded="mano", what="attachment.npz")
    with pytest.raises(HandcapError, match="not a folder"):
        hand_model_from_options(recorded="mano")  # HANDCAP_MANO_DIR points nowhere
    monkeypatch.setenv("HANDCAP_MANO_DIR", str(mano_dir))
    assert isinstance(hand_model_from_options(recorded="mano"), ManoHand)
    with pytest.raises(HandcapError, match="unknown hand model 'smplx'"):
        hand_model_from_options(recorded="smplx")
