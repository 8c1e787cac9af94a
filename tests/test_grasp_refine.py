"""Test-time refinement of sampled grasps (ohra.learn.grasp.refine): fingers sunk into the object are
opened just enough to clear it; nothing else moves."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.canonical.kinematics import HandModel
from ohra.errors import GraspError
from ohra.hands import get_hand
from ohra.learn.grasp.refine import RefineSettings, refine_grasps
from ohra.objects.model import ObjectModel
from ohra.rotations import matrix_to_rot6d
from scipy.spatial.transform import Rotation


def _sunk_grasps(hand: HandModel, obj: ObjectModel, n: int, seed: int = 0, depth: float = 0.005) -> np.ndarray:
    """A model's typical error, made by the joints: random palm orientations facing the object, each
    palm as close as its open fingers (20 % closed) stay 2 mm clear, then the fingers closed until one
    sinks ``depth`` into the object (grasps where none does are dropped)."""
    from ohra.synth.pipeline import finger_object_distance

    R = Rotation.random(n, random_state=seed).as_matrix()
    x = R[:, :, 0]  # palm normal, toward the object
    lo, up = hand.lower, hand.upper
    out = np.concatenate([np.zeros((n, 3)), matrix_to_rot6d(R), np.tile(lo + 0.2 * (up - lo), (n, 1))], axis=1)
    placed = np.zeros(n, dtype=bool)
    for r in np.arange(obj.radius + 0.15, 0.0, -0.0005):  # palm from far to near, fingers open
        g = out.copy()
        g[:, :3] = -x * r
        ok = finger_object_distance(hand, obj, g) >= 0.002
        out[~placed & ok, :3] = g[~placed & ok, :3]
        placed |= ~ok & (np.linalg.norm(out[:, :3], axis=1) > 0)  # the last clear distance is kept
    sunk = np.zeros(n, dtype=bool)
    for a in np.linspace(0.2, 1.0, 161):  # close the fingers
        g = out.copy()
        g[:, 9:] = lo + a * (up - lo)
        hit = ~sunk & (finger_object_distance(hand, obj, g) <= -depth)
        out[hit, 9:], sunk = g[hit, 9:], sunk | hit
    return out[sunk]


@pytest.fixture(scope="module")
def case():
    hand = HandModel.from_params(get_hand("allegro_hand_left"))
    obj = ObjectModel.builtin("sphere")
    g = _sunk_grasps(hand, obj, 24)
    return hand, obj, g, refine_grasps(hand, obj, g)


def test_sunk_fingers_come_out_to_the_clearance(case):
    hand, obj, g, r = case
    sunk = r.min_distance_before < -0.003
    assert sunk.sum() >= 20  # the fixture does sink fingers
    s = RefineSettings()
    # 0.1 mm margin: the last step's length
    assert np.all(r.min_distance_after[sunk] >= -s.clearance_m - 0.0001), r.min_distance_after[sunk]


def test_only_joints_move_and_they_stay_within_the_limits(case):
    hand, _, g, r = case
    assert np.array_equal(r.grasps[:, :9], g[:, :9])
    assert np.all(r.grasps[:, 9:] >= hand.lower - 1e-12) and np.all(r.grasps[:, 9:] <= hand.upper + 1e-12)
    fixed = hand.upper <= hand.lower  # absent and fixed joints
    assert np.array_equal(r.grasps[:, 9:][:, fixed], g[:, 9:][:, fixed])


def test_the_refinement_opens_as_little_as_it_needs(case):
    """A grasp 1 mm deep is left alone at 1 mm clearance and moved only slightly at 0 mm."""
    hand, obj, g, r = case
    moved = np.abs(r.grasps[:, 9:] - g[:, 9:]).max(axis=1)
    assert np.all(moved[r.steps == 0] == 0)
    assert np.median(moved[r.steps > 0]) < 0.5  # rad: a nudge, not a reset to the open hand


def test_clear_grasps_are_returned_unchanged_and_the_result_is_deterministic(case):
    hand, obj, g, r = case
    clear = r.min_distance_before >= -RefineSettings().clearance_m
    again = refine_grasps(hand, obj, g[clear])
    assert np.array_equal(again.grasps, g[clear]) and np.all(again.steps == 0)
    assert np.array_equal(refine_grasps(hand, obj, g).grasps, r.grasps)


def test_any_canonical_hand_works_leap_variants_included():
    p = get_hand("leap_3033")
    hand = HandModel.from_params(p)
    obj = ObjectModel.builtin("box")
    g = _sunk_grasps(hand, obj, 12, seed=1)
    assert len(g) >= 3
    r = refine_grasps(p, obj, g)
    absent = ~np.asarray(p.present_joints, dtype=bool) if hasattr(p, "present_joints") else hand.upper <= hand.lower
    assert np.all(r.grasps[:, 9:][:, absent] == 0)
    assert np.all(r.min_distance_after >= -RefineSettings().clearance_m - 0.0001), r.min_distance_after


def test_a_hand_without_fingers_has_nothing_to_refine_or_measure():
    """leap_0000 (a palm alone) crashed refinement, touch and nearest-surface choice with numpy reduction errors."""
    from ohra.learn.grasp.model import nearest_surface
    from ohra.learn.grasp.refine import finger_clearance, finger_distances

    p = get_hand("leap_0000")
    obj = ObjectModel.builtin("box")
    g = np.zeros((3, 31))
    g[:, 0] = 0.1
    g[:, 3:9] = matrix_to_rot6d(Rotation.random(3, random_state=0).as_matrix())
    for touch in (False, True):
        r = refine_grasps(p, obj, g, RefineSettings(touch=touch))
        np.testing.assert_array_equal(r.grasps, g)
        assert np.all(r.steps == 0) and np.all(np.isinf(r.min_distance_before)) and np.all(np.isinf(r.min_distance_after))
    assert np.all(np.isinf(finger_clearance(p, obj, g))) and finger_distances(p, obj, g).shape == (3, 0)
    np.testing.assert_array_equal(nearest_surface(p, obj, np.stack([g, g + 0.01], axis=1)), g)


@pytest.mark.parametrize("kwargs", [dict(touch="no"), dict(clearance_m=float("nan")), dict(iterations=2.5),
                                    dict(samples_per_capsule=True), dict(step_rad="0.03")])
def test_settings_that_would_be_misread_are_refused(kwargs):
    """touch="no" switched touch on; a NaN clearance silently refined nothing; 2.5 iterations passed int()."""
    with pytest.raises(GraspError, match="RefineSettings: "):
        RefineSettings(**kwargs)
    assert RefineSettings(touch=np.bool_(True), iterations=np.int64(3)).touch


def test_bad_input_is_refused():
    hand = HandModel.from_params(get_hand("allegro_hand_left"))
    with pytest.raises(GraspError, match=r"\(N, 31\)"):
        refine_grasps(hand, ObjectModel.builtin("sphere"), np.zeros((3, 30)))
    with pytest.raises(GraspError, match="step_rad"):
        RefineSettings(step_rad=0.0)


def test_the_model_refines_its_own_samples_on_request(tmp_path):
    """``sample(refine=True)`` = the plain sample with the fingers cleared; ``evaluate_model`` records it."""
    pytest.importorskip("torch")
    from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset

    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.train import train_grasp

    model = train_grasp(write_dataset(tmp_path), tiny_model_config(condition="params"), tiny_train_config(),
                        progress=False).model
    obj = ObjectModel.builtin("cylinder")
    timing: dict = {}
    raw = model.sample("barrett_hand", obj, 16, seed=2)
    ref = model.sample("barrett_hand", obj, 16, seed=2, refine=True, timing=timing)
    assert np.array_equal(ref, refine_grasps(get_hand("barrett_hand"), obj, raw).grasps)
    assert np.array_equal(ref[:, :9], raw[:, :9]) and timing["refine_seconds"] > 0
    rep = evaluate_model(model, ["barrett_hand"], [obj], n=2, refine=True, allow_seen=True)
    assert rep.meta["refine"]["clearance_m"] == RefineSettings().clearance_m
    assert evaluate_model(model, ["barrett_hand"], [obj], n=2, allow_seen=True).meta["refine"] is None


def test_nearest_surface_keeps_the_draw_whose_fingers_just_touch():
    """Of K draws per rotation, the one whose deepest finger point is nearest the surface is kept:
    not the deepest (sunk), not the farthest (hovering)."""
    from ohra.learn.grasp.model import nearest_surface
    from ohra.learn.grasp.refine import finger_clearance

    p = get_hand("allegro_hand_left")
    hand, obj = HandModel.from_params(p), ObjectModel.builtin("sphere")
    g = _sunk_grasps(hand, obj, 6, depth=0.004)
    normal = _rot6d_to_matrix(g[:, 3:9])[:, :, 0]  # palm normal, toward the object
    # per rotation: the sunk grasp, the palm 4 mm back (about touching), 3 cm back (hovering), 4 mm further in (deeper)
    offsets = np.array([0.0, -0.004, -0.03, 0.004])
    cand = np.repeat(g[:, None], len(offsets), axis=1)
    cand[:, :, :3] += offsets[None, :, None] * normal[:, None, :]
    d = finger_clearance(p, obj, cand.reshape(-1, 31)).reshape(cand.shape[:2])
    want = np.abs(d).argmin(axis=1)
    assert np.all(d[np.arange(len(g)), want] > -0.0035) and np.all(d[:, 2] > 0.01)  # the set-up: one near, one far
    kept = nearest_surface(p, obj, cand)
    assert np.array_equal(kept, cand[np.arange(len(g)), want])
    assert not np.array_equal(kept, cand[:, 0]) and not np.array_equal(kept, cand[:, 2])


def _rot6d_to_matrix(r6: np.ndarray) -> np.ndarray:
    from ohra.rotations import rot6d_to_matrix

    return rot6d_to_matrix(r6)


def test_the_model_chooses_among_draws_on_request(tmp_path):
    """``sample(candidates=K)``: the same wrist rotations, fingers nearer the surface than the first draw's;
    K=1 is the plain sample; bad K is an ohra error; ``evaluate_model`` records it."""
    pytest.importorskip("torch")
    from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset

    from ohra.learn.grasp.evaluate import evaluate_model
    from ohra.learn.grasp.refine import finger_clearance
    from ohra.learn.grasp.train import train_grasp

    model = train_grasp(write_dataset(tmp_path), tiny_model_config(condition="params"), tiny_train_config(),
                        progress=False).model
    obj = ObjectModel.builtin("cylinder")
    raw = model.sample("barrett_hand", obj, 48, seed=2)
    assert np.array_equal(model.sample("barrett_hand", obj, 48, seed=2, candidates=1), raw)
    best = model.sample("barrett_hand", obj, 48, seed=2, candidates=6)
    assert np.allclose(best[:, 3:9], raw[:, 3:9])  # the same rotations
    p = get_hand("barrett_hand")
    # the best of 6 draws is at least as near the surface as one other draw 6 times in 7; a single draw, half the time
    nearer = np.abs(finger_clearance(p, obj, best)) <= np.abs(finger_clearance(p, obj, raw))
    assert nearer.mean() >= 0.7, nearer.mean()
    for bad in (0, -1, 2.5, True):
        with pytest.raises(GraspError, match="candidates"):
            model.sample("barrett_hand", obj, 2, candidates=bad)
    assert evaluate_model(model, ["barrett_hand"], [obj], n=2, allow_seen=True, candidates=3).meta["candidates"] == 3


def _finger_distances(hand: HandModel, obj: ObjectModel, g: np.ndarray) -> np.ndarray:
    """(N, fingers) each finger's nearest capsule-core sample to the object, minus the radius [m]."""
    from ohra.rotations import grasp_to_pose

    T, q = grasp_to_pose(g)
    caps = hand.capsules(q)
    u = np.linspace(0.0, 1.0, RefineSettings().samples_per_capsule)[:, None, None]
    pts = caps.p0[:, None] + u * (caps.p1 - caps.p0)[:, None]
    world = np.einsum("nij,nskj->nski", T[:, :3, :3], pts) + T[:, None, None, :3, 3]
    d = (obj.signed_distance(world.reshape(-1, 3)).reshape(world.shape[:3]) - caps.radius).min(axis=1)
    return np.stack([d[:, caps.finger == f].min(axis=1) for f in np.unique(caps.finger)], axis=1)


def _data_grasps_with_joint_error(hand_name: str = "shadow_hand_right", obj_name: str = "capsule-0", sigma: float = 0.15):
    """Robust grasps of the committed dataset (every finger within 2 mm of the surface) with seeded joint
    noise of ``sigma`` [rad], the size of the grasp model's joint error: some fingers sunk, some hovering."""
    from pathlib import Path

    from ohra.data import GraspDataset
    from ohra.learn.grasp.data import load_dataset_object

    root = Path(__file__).resolve().parents[1] / "datasets" / "grasp_unified_s0"
    ds = GraspDataset([root], hands=[hand_name])
    for (r, _, o, sh), (_, _, g) in zip(ds.entries, ds):
        if o == obj_name:
            hand = HandModel.from_params(get_hand(hand_name))
            g = np.asarray(g[:8], dtype=float)
            noise = np.random.default_rng(0).normal(0.0, sigma, (len(g), 22)) * (hand.upper > hand.lower)
            g[:, 9:] = np.clip(g[:, 9:] + noise, hand.lower, hand.upper)
            return hand, load_dataset_object(r, o, sh.get("object", {}), {}), g
    raise AssertionError(f"{obj_name} not in {root}")


def test_touch_also_closes_hovering_fingers_onto_the_surface():
    """Opening alone leaves the hovering fingers where they are; ``touch`` brings every finger within
    the clearance of the surface, as in the data, and sinks none."""
    hand, obj, g = _data_grasps_with_joint_error()
    before = _finger_distances(hand, obj, g)
    assert np.mean(before > 0.002) > 0.3 and np.mean(before < -0.002) > 0.2  # both kinds of error
    from ohra.learn.grasp.refine import finger_distances

    np.testing.assert_allclose(finger_distances(hand, obj, g), before)  # the library's measure is this one
    opened = _finger_distances(hand, obj, refine_grasps(hand, obj, g).grasps)
    assert np.mean(opened > 0.002) > 0.3
    touched = refine_grasps(hand, obj, g, RefineSettings(touch=True))
    after = _finger_distances(hand, obj, touched.grasps)
    s = RefineSettings()
    assert np.mean(np.abs(after) <= s.clearance_m + 0.001) > 0.95, after
    assert np.all(after >= -s.clearance_m - 0.0001)  # and none is sunk
    assert np.array_equal(touched.grasps[:, :9], g[:, :9])  # the palm stays


def test_settings_text_without_touch_is_what_caches_made_before_it_hold():
    assert repr(RefineSettings()) == "RefineSettings(clearance_m=0.001, iterations=30, step_rad=0.03, samples_per_capsule=5, fd_rad=0.001)"
    assert repr(RefineSettings(touch=True)).endswith("touch=True)")


def test_cli_refine_takes_open_or_touch(tmp_path, capsys):
    """``--refine`` alone opens sunk fingers (as before the choice existed); ``--refine touch`` also closes the
    hovering ones: both are the library's refinements of the same samples."""
    pytest.importorskip("torch")
    import importlib

    from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset

    from ohra.learn.grasp.train import train_grasp

    run = tmp_path / "run"
    train_grasp(write_dataset(tmp_path / "ds"), tiny_model_config(condition="params"), tiny_train_config(), run, progress=False)
    cli = importlib.import_module("ohra.cli.main").main
    out = {}
    for how in ([], ["--refine"], ["--refine", "touch"]):
        f = tmp_path / f"g{len(how)}.npz"
        assert cli(["grasp", "sample", "--model", str(run), "--hand", "barrett_hand", "--object", "builtin:cylinder", "-n", "6",
                    "--seed", "2", *how, "-o", str(f)]) == 0
        with np.load(f) as z:
            out[tuple(how)] = z["grasps"]
    obj, p = ObjectModel.builtin("cylinder"), get_hand("barrett_hand")
    raw = out[()]
    np.testing.assert_allclose(out[("--refine",)], refine_grasps(p, obj, raw).grasps)
    np.testing.assert_allclose(out[("--refine", "touch")], refine_grasps(p, obj, raw, RefineSettings(touch=True)).grasps)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # argparse's usage error
        cli(["grasp", "sample", "--model", str(run), "--hand", "barrett_hand", "--object", "builtin:cylinder",
             "--refine", "squeeze", "-o", str(tmp_path / "x.npz")])
    assert exc.value.code == 2 and "choose from 'open', 'touch'" in capsys.readouterr().err


def _full_gradient_refine(hand, obj, g, s):
    """The refinement as first written: every finite-difference step measures every capsule again."""
    from ohra.learn.grasp.refine import _penetration
    from ohra.rotations import grasp_to_pose

    T, q = grasp_to_pose(g.astype(float))
    q = q.copy()
    movable = np.flatnonzero(hand.upper > hand.lower)
    E, _ = _penetration(hand, obj, T, q, s)
    step, steps = np.full(len(g), s.step_rad), np.zeros(len(g), dtype=int)
    for _ in range(s.iterations):
        act = np.flatnonzero((E > 0) & (step > 1e-4))
        if not act.size:
            break
        grad = np.zeros((len(act), 22))
        for j in movable:
            qj = q[act].copy()
            qj[:, j] += s.fd_rad
            grad[:, j] = (_penetration(hand, obj, T[act], qj, s)[0] - E[act]) / s.fd_rad
        trial = np.clip(q[act] - step[act, None] * grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-12),
                        hand.lower, hand.upper)
        E_new, _ = _penetration(hand, obj, T[act], trial, s)
        better = E_new < E[act]
        q[act[better]], E[act[better]] = trial[better], E_new[better]
        steps[act[better]] += 1
        step[act[~better]] *= 0.5
    return q, steps


def test_measuring_only_the_capsules_a_joint_moves_changes_no_bit(case, objects_dir):
    """The gradient measures again only the capsules that hang from the perturbed joint (2-4x faster on
    V-HACD bodies): the refined grasps are bit for bit those of measuring every capsule, on an exact body
    (the sphere) and on a union of convex pieces (a YCB bottle)."""
    from ohra.learn.grasp.model import load_grasp_model, resolve_object

    hand, sphere, g, _ = case
    bottle = resolve_object(str(objects_dir / "ycb" / "MustardBottle"))
    assert len(bottle.body.pieces) > 1
    s = RefineSettings(touch=True)  # both energies: sunk samples and hovering fingers
    sampled = load_grasp_model().sample("allegro_hand_left", bottle, 4, seed=0)
    for obj, grasps in ((sphere, g[:6]), (bottle, sampled)):
        r = refine_grasps(hand, obj, grasps, s)
        q, steps = _full_gradient_refine(hand, obj, grasps, s)
        assert steps.sum() > 0 and np.array_equal(r.steps, steps)
        assert np.array_equal(r.grasps[:, 9:], q)
