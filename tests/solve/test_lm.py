"""The Levenberg-Marquardt pieces on their own: the priors' Jacobian, and a warm start that brings its kinematics."""

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.hand import OpenHand
from handcap.hand.anatomy import PHI_LIMITS
from handcap.solve.lm import N_PRIOR_ROWS, Poses, Priors, frame_costs, held_angles, levenberg_marquardt, prior_terms
from handcap.solve.markers import MarkerModel


def test_prior_jacobian_matches_finite_differences():
    # Angles kept away from the limits' kinks by at least the step, so the central difference is exact there.
    rng = np.random.default_rng(3)
    low, high = PHI_LIMITS[:, 0], PHI_LIMITS[:, 1]
    phi = np.where(rng.random((4, 27)) < 0.3, high + rng.uniform(0.05, 0.3, (4, 27)),
                   low + (high - low) * rng.uniform(0.1, 0.9, (4, 27)))
    held = rng.random((4, 27)) < 0.3
    free = rng.random((4, 27)) < 0.5
    priors = Priors()
    residuals, jacobian = prior_terms(phi, priors, held, free)
    assert residuals.shape == (4, N_PRIOR_ROWS) and jacobian.shape == (4, N_PRIOR_ROWS, 27)
    step = 1e-6
    numeric = np.empty_like(jacobian)
    for k in range(27):
        up, down = phi.copy(), phi.copy()
        up[:, k] += step
        down[:, k] -= step
        numeric[:, :, k] = (prior_terms(up, priors, held, free)[0] - prior_terms(down, priors, held, free)[0]) / (
            2 * step)
    assert np.abs(numeric - jacobian).max() < 1e-8
    # the rest pull: only on angles not held, towards the relaxed hand
    rest = residuals[:, -27:]
    assert np.allclose(rest, priors.rest_weight * (phi - priors.rest_phi()) * ~held)


def test_warm_start_with_its_kinematics_gives_the_same_fit(glove_session):
    # A stream's frame starts from the pose the frame before returned; handing over that pose's kinematics
    # (start_kin) skips a forward pass and must change nothing.
    _, take = glove_session
    model = MarkerModel(OpenHand(take.hand_motion.side), take.attachment)
    names = list(take.attachment.marker_names)
    positions = take.markers.select(names).positions
    observed = np.isfinite(positions).all(axis=2)
    target = np.nan_to_num(positions)
    truth = take.hand_motion
    start = Poses(truth.transl[:1] + 0.002, Rotation.from_rotvec(truth.global_orient[:1]).as_matrix(),
                  np.zeros((1, 27)))
    first, _, parts = levenberg_marquardt(model, target[:1], observed[:1], start, Priors(), iterations=20,
                                          return_parts=True)
    held = held_angles(model, observed[1:2])
    plain = levenberg_marquardt(model, target[1:2], observed[1:2], first, Priors(), iterations=1, held=held)
    warm = levenberg_marquardt(model, target[1:2], observed[1:2], first, Priors(), iterations=1, held=held,
                               start_kin=parts[0])
    for a, b in zip((plain[0].transl, plain[0].rot, plain[0].phi, plain[1]),
                    (warm[0].transl, warm[0].rot, warm[0].phi, warm[1])):
        assert np.array_equal(a, b)
    # the kinematics returned are those of the pose returned
    recomputed = frame_costs(model, first, target[:1], observed[:1], held_angles(model, observed[:1]), Priors(),
                             0.005)[1][0]
    for a, b in zip(parts[0], recomputed):
        assert np.allclose(a, b, atol=1e-12)



def test_a_dip_the_markers_see_is_solved_from_them_not_from_the_coupling():
    # A ring finger wrapped round something: its DIP bent 70 deg over a PIP of 25 (the tendon coupling says 17).
    # joints-19 puts markers on the DIP and the tip, so the markers set the angle; the coupling at its full weight
    # (0.01, as everywhere before) left it 36 deg short.
    from handcap import MarkerSequence
    from handcap.hand.attachment import MarkerAttachment
    from handcap.hand.anatomy import PHI_NAMES, relaxed_pose
    from handcap.layouts import load_layout
    from handcap.solve import solve_hand

    hand = OpenHand()
    attachment = MarkerAttachment.from_layout(load_layout("joints-19"), hand)
    rng = np.random.default_rng(5)
    n = 12
    i = {name: k for k, name in enumerate(PHI_NAMES)}
    phi = np.repeat(relaxed_pose()[None], n, axis=0)
    phi[:, i["ring_pip_bend"]] = np.deg2rad(25 + rng.normal(0, 1, n))
    phi[:, i["ring_dip_bend"]] = np.deg2rad(70 + rng.normal(0, 1, n))
    rot = Rotation.from_rotvec(rng.normal(0, 0.05, (n, 3))).as_matrix()
    transl = np.array([0.0, 0.0, 0.5]) + rng.normal(0, 0.002, (n, 3))
    positions = MarkerModel(hand, attachment).positions(transl, rot, phi) + rng.normal(0, 0.0003, (n, 19 + 3, 3))
    markers = MarkerSequence(positions, list(attachment.marker_names), 50.0)
    for priors, low, high in ((Priors(), 60, 75), (Priors(seen_coupling_weight=0.01), 0, 50)):  # 66.6, 33.6
        solved = np.rad2deg(solve_hand(markers, attachment, priors=priors).phi[:, i["ring_dip_bend"]])
        assert low < solved.mean() < high, (priors.seen_coupling_weight, solved.mean())
    # The coupling's full weight stays where no marker sets the DIP: that prior row weighs 10 times more.
    free = np.zeros((1, 27), bool)
    free[0, i["ring_dip_bend"]] = True
    row = 27 + 3  # the ring finger's coupling row (index, middle, pinky, ring)
    seen = prior_terms(phi[:1], Priors(), np.zeros((1, 27), bool), np.zeros((1, 27), bool))[0][0, row]
    unseen = prior_terms(phi[:1], Priors(), np.zeros((1, 27), bool), free)[0][0, row]
    assert np.isclose(unseen, 10 * seen) and abs(unseen) > 0.005
