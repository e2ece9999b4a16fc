"""Synthetic grasps rest on their object: no frame of the true hand lies deeper in it than the skin gives.

The depths are measured independently of the planner: the posed hand's vertices (shape, wrist and angles of each
frame) against the object's analytic signed distance in its pose of that frame.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.hand import load_hand_model
from handcap.hand.anatomy import PHI_NAMES, finger_flexion, pose_from_degrees
from handcap.hand.openhand import OpenHand
from handcap.synth.grasps import SQUEEZE, close_until_contact, grasp_configuration, rest_on_object, steady_wrist
from handcap.synth.motions import make_motion, rest_path
from handcap.synth.objects import make_object

TOL = 1e-5  # metres: the planner's own margin is 1e-7; the skinning is evaluated again here


def _depths(hand, obj, motion, betas=None):
    """Deepest vertex of the hand in the object in each frame (T,), metres (positive: inside)."""
    verts = hand.forward(betas, motion.global_orient, None, motion.transl, phi=motion.phi).vertices
    rot = Rotation.from_rotvec(motion.object_rotation).as_matrix()
    local = np.einsum("tvi,tij->tvj", verts - motion.object_translation[:, None], rot)
    return -obj.signed_distance(local.reshape(-1, 3)).reshape(len(verts), -1).min(axis=1)


@pytest.mark.parametrize(("name", "kind", "seed"), [("grasp", "cylinder", 4), ("grasp", "sphere", 1),
                                                    ("grasp", "cuboid", 2), ("precision", "sphere", 0),
                                                    ("precision", "cylinder", 3)])
def test_a_held_object_is_not_pressed_in_deeper_than_skin_gives(name, kind, seed):
    # Before: splines through repeated keys swung the hand 14-21 mm into the object as it closed, and held
    # fingers pressed up to 19 mm in (the key pose 3.5 mm: each joint could add its own 1.5 mm).
    hand, obj = load_hand_model(), make_object(kind)
    motion = make_motion(name, hand, 200, 50.0, np.random.default_rng(seed), obj)
    depth = _depths(hand, obj, motion)
    assert depth.max() <= SQUEEZE + TOL, f"{depth.max() * 1e3:.2f} mm in at frame {depth.argmax()}"
    held = depth[motion.holding]
    assert np.median(held) > 0.0  # and it does touch what it carries
    # The key pose alone.
    object2hand, _, grasp_phi = grasp_configuration(hand, obj, "power" if name == "grasp" else "precision")
    verts = hand.forward(phi=grasp_phi).vertices
    local = (verts - object2hand[:3, 3]) @ object2hand[:3, :3]
    assert -obj.signed_distance(local).min() <= SQUEEZE + TOL


@pytest.mark.parametrize(("name", "kind", "seed", "bound"), [("precision", "sphere", 1, SQUEEZE + TOL),
                                                            ("rotate-cube", "cube2x2", 1, 0.004)])
def test_the_hand_comes_and_goes_clear_of_the_object(name, kind, seed, bound):
    # Shapes drawn as synth draws them. Before: the hand turned as it rose off the object and swept a relaxed
    # finger into it (the ring finger 2.7 mm into the sphere, 8 mm into the cube), and the cube turned about the
    # line between the fingertips ended inside the index finger (up to 22 mm). The cube's corners sweep past the
    # fingers as it turns: 2.7 mm here.
    hand, obj = load_hand_model(), make_object(kind)
    rng = np.random.default_rng(seed)
    betas = rng.normal(0.0, 0.5, 10)
    motion = make_motion(name, hand, 200, 50.0, rng, obj, betas=betas)
    depth = _depths(hand, obj, motion, betas)
    assert depth.max() <= bound, f"{depth.max() * 1e3:.2f} mm in at frame {depth.argmax()}"


def test_the_grasp_is_planned_for_the_subjects_hand():
    hand, obj = load_hand_model(), make_object("cylinder")
    big = np.zeros(10)
    big[0] = 2.0  # a large hand
    assert hand.rest_joints(big)[18, 0] > 1.05 * hand.rest_joints()[18, 0]
    for betas, bound in ((big, SQUEEZE + TOL), (None, None)):
        motion = make_motion("grasp", hand, 150, 40.0, np.random.default_rng(0), obj, betas=betas)
        depth = _depths(hand, obj, motion, big)
        if bound:
            assert depth.max() <= bound
        else:  # the average hand's grasp, worn by the large hand, presses it in
            assert depth.max() > SQUEEZE + 0.001


def test_rest_path_rests_at_each_key_and_never_overshoots():
    times = np.array([0.0, 0.5, 1.0, 2.0, 2.5])
    values = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, -2.0], [0.0, 0.0]])
    t = np.linspace(-0.1, 2.6, 2701)
    path = rest_path(times, values, t)
    for key, value in zip(times, values):
        np.testing.assert_allclose(path[np.argmin(np.abs(t - key))], value, atol=1e-12)
    # Between two keys the path stays between their values (a spline through these keys leaves that range).
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    low, high = np.minimum(values[k], values[k + 1]), np.maximum(values[k], values[k + 1])
    assert np.all(path >= low - 1e-12) and np.all(path <= high + 1e-12)
    velocity = np.gradient(path, t, axis=0)
    for key in times:
        assert np.abs(velocity[np.argmin(np.abs(t - key))]).max() < 1e-3
    # The peak speed of a minimum-jerk move is 15/8 of its mean.
    assert np.abs(velocity).max() <= 1.875 * (np.abs(np.diff(values, axis=0)) / np.diff(times)[:, None]).max() + 1e-3


def test_tremor_that_would_press_a_finger_in_is_held_back_and_other_tremor_kept():
    hand, obj = load_hand_model(), make_object("sphere")
    object2hand, open_phi, grasp_phi = grasp_configuration(hand, obj, "power")
    n = 12
    rng = np.random.default_rng(0)
    smooth = np.repeat(grasp_phi[None], n, axis=0)
    shaken = smooth + np.deg2rad(rng.normal(0.0, 4.0, smooth.shape))
    out = rest_on_object(hand, obj, np.repeat(object2hand[None], n, axis=0), smooth, shaken, open_phi, 50.0)
    verts = hand.forward(phi=np.concatenate([shaken, out])).vertices
    depth = -obj.signed_distance((verts - object2hand[:3, 3]) @ object2hand[:3, :3]).min(axis=1)
    assert depth[:n].max() > SQUEEZE + 0.001  # the shaken hand pressed in
    assert depth[n:].max() <= SQUEEZE + TOL
    # Each digit's angles are its shaken ones scaled back towards the plan by 1, 1/2, 1/4 or 0.
    scale = (out - smooth)[:, :20].reshape(n, 4, 5) / (shaken - smooth)[:, :20].reshape(n, 4, 5)
    assert np.all(np.isin(np.round(scale, 9), [0.0, 0.25, 0.5, 1.0]))
    assert (np.ptp(scale, axis=2) < 1e-9).all()
    assert (scale == 1.0).any() and (scale < 1.0).any()



def test_the_wrists_tremor_does_not_press_the_hand_into_the_object_on_the_table():
    # Before: this left hand's middle finger went 2.6 mm into the cylinder as it closed on it (frame 30, not yet
    # held), pressed in by the wrist's tremor; without that tremor 1.5 mm.
    hand, obj = OpenHand("left"), make_object("cylinder", seed=0)
    rng = np.random.default_rng(0)
    betas = rng.normal(0.0, 0.5, 10)
    motion = make_motion("grasp", hand, 120, 30.0, rng, obj, betas=betas)
    depth = _depths(hand, obj, motion, betas)
    assert depth.max() <= SQUEEZE + TOL, f"{depth.max() * 1e3:.2f} mm in at frame {depth.argmax()}"


def test_wrist_tremor_that_would_press_the_hand_in_is_held_back_and_other_tremor_kept():
    hand, obj = load_hand_model(), make_object("sphere")
    object2hand, open_phi, _ = grasp_configuration(hand, obj, "power")  # the open hand about to close on it
    n = 16
    rng = np.random.default_rng(0)
    phi = np.repeat(open_phi[None], n, axis=0)
    object_pose = np.repeat(object2hand[None], n, axis=0)  # the hand model's frame is the world's
    smooth = np.repeat(np.eye(4)[None], n, axis=0)
    turns = Rotation.from_rotvec(np.deg2rad(rng.normal(0.0, 1.0, (n, 3))))
    shaken = smooth.copy()
    shaken[:, :3, :3] = turns.as_matrix()
    shaken[:, :3, 3] = rng.normal(0.0, 0.003, (n, 3))
    out = steady_wrist(hand, obj, object_pose, smooth, shaken, phi)

    def depth(wrists):  # the posed hands' deepest vertex in the sphere, metres (positive: inside)
        verts = hand.forward(None, Rotation.from_matrix(wrists[:, :3, :3]).as_rotvec(), None, wrists[:, :3, 3],
                             phi=phi).vertices
        return -obj.signed_distance((verts - object2hand[:3, 3]) @ object2hand[:3, :3]).min(axis=1)

    planned = depth(smooth)
    assert depth(shaken).max() > max(SQUEEZE, planned.max()) + 0.001  # the shaken wrist pressed the hand in
    assert (depth(out) <= np.maximum(SQUEEZE, planned) + TOL).all()
    # Each wrist's turn and shift are its shaken ones scaled back by 1, 1/2, 1/4 or 0.
    shift = (out[:, :3, 3] / shaken[:, :3, 3]).round(9)
    turn = (Rotation.from_matrix(out[:, :3, :3]).as_rotvec() / turns.as_rotvec()).round(9)
    assert np.isin(shift, [0.0, 0.25, 0.5, 1.0]).all() and (np.ptp(shift, axis=1) == 0).all()
    assert np.allclose(turn, shift)
    assert (shift == 1.0).any() and (shift < 1.0).any()


@pytest.mark.parametrize("shape", ["cylinder", "sphere", "cuboid", "cube2x2"])
def test_fingers_close_all_joints_together_and_stop_where_they_touch(shape):
    # Before: each finger closed joint after joint (MCP, then PIP, then DIP), so a DIP could curl fully while the
    # PIP stayed nearly straight (the middle finger round the cylinder: PIP 64, DIP 16 degrees; the little finger
    # round the sphere: PIP 13, DIP 73), which no human grasp does.
    hand, obj = load_hand_model(), make_object(shape)
    object2hand, open_phi, _ = grasp_configuration(hand, obj, "power")
    closed = pose_from_degrees(thumb_cmc_bend=70, thumb_cmc_spread=-30, thumb_cmc_twist=30, thumb_mcp_bend=55,
                               thumb_ip_bend=80)
    for finger in ("index", "middle", "ring", "pinky"):
        closed = finger_flexion(closed, finger, 1.2, pip=100)
    digits = ("index", "middle", "ring", "pinky", "thumb")
    phi, contact = close_until_contact(hand, obj, object2hand, open_phi, closed, digits)
    verts = hand.forward(phi=phi).vertices
    depth = obj.signed_distance((verts - object2hand[:3, 3]) @ object2hand[:3, :3])
    assert depth.min() >= -SQUEEZE - TOL
    joints = {f: (f"{f}_mcp_bend", f"{f}_pip_bend", f"{f}_dip_bend") for f in digits[:4]}
    joints["thumb"] = ("thumb_cmc_bend", "thumb_mcp_bend", "thumb_ip_bend")
    links = ("proximal", "middle", "distal")
    for finger in digits:
        idx = [PHI_NAMES.index(n) for n in joints[finger]]
        # How far each joint went from open to closed: the same for all until a phalanx touched, then no less.
        fraction = (phi[idx] - open_phi[idx]) / (closed[idx] - open_phi[idx])
        assert np.all(np.diff(fraction) >= -1e-9), (finger, fraction)
        # A joint that stopped short of closed stopped because its phalanx, or one after it, touched.
        for j in np.flatnonzero(fraction < 1 - 1e-9):
            moved = np.isin(hand.segment_of_vertex, [hand.segment_id(f"{finger}_{s}") for s in links[j:]])
            assert contact[finger] and depth[moved].min() < 0.001, (finger, links[j], depth[moved].min())


def test_each_take_grasps_its_own_way_and_rests_on_the_object():
    # Before: every take's grasp of an object was the same pose but for the subject's hand shape.
    hand, obj = load_hand_model(), make_object("cylinder")
    grasps = [grasp_configuration(hand, obj, "power", rng=np.random.default_rng(seed)) for seed in range(3)]
    planned = grasp_configuration(hand, obj, "power")
    again = grasp_configuration(hand, obj, "power")
    assert all(np.array_equal(a, b) for a, b in zip(planned, again))  # without a generator: one grasp
    for object2hand, _, phi in grasps:
        verts = hand.forward(phi=phi).vertices
        depth = obj.signed_distance((verts - object2hand[:3, 3]) @ object2hand[:3, :3])
        assert -SQUEEZE - TOL <= depth.min() < 0.001  # it touches, no deeper than the skin gives
    phis = np.array([g[2] for g in grasps])
    spread = np.rad2deg(np.ptp(phis, axis=0)).max()
    assert spread > 5.0  # degrees: some joint differs between the takes' grasps
    moved = np.linalg.norm(np.ptp([g[0][:3, 3] for g in grasps], axis=0))
    assert 0.0005 < moved < 0.03  # metres: the object sits elsewhere in the hand, still in it
