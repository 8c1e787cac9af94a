"""The finger-object training terms: capsules as Pinocchio places them, the object's signed distance
from a grid, a penetration term that is zero for a clear grasp, grows with depth and opens sunk fingers,
a two-sided contact term that is zero at the data's fingers, pulls hovering fingers onto the surface and
sunk ones out of it, and ignores links clear of the object in both, and training options that change
nothing when off."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from grasp_fixtures import HANDS, tiny_model_config, tiny_train_config, write_dataset  # noqa: E402

from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.errors import CheckpointError  # noqa: E402
from ohra.hands import get_hand  # noqa: E402
from ohra.learn.grasp.config import GraspConfigError  # noqa: E402
from ohra.learn.grasp.contact import FingerCapsules, SDFGrids, contact_gap, link_distances, penetration  # noqa: E402
from ohra.learn.grasp.refine import finger_clearance  # noqa: E402
from ohra.learn.grasp.train import train_grasp  # noqa: E402
from ohra.objects.model import ObjectModel  # noqa: E402
from ohra.rotations import grasp_to_pose, matrix_to_rot6d  # noqa: E402


@pytest.fixture(scope="module")
def caps():
    return FingerCapsules([get_hand(h) for h in HANDS], HANDS)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("contact") / "ds")


def test_capsule_cores_are_where_pinocchio_puts_the_capsules(caps):
    for i, h in enumerate(HANDS):
        hm = HandModel.from_params(get_hand(h))
        q = hm.random_configurations(6, seed=i)
        c = hm.capsules(q)
        pts, r, mask = caps.points(torch.full((6,), i), torch.from_numpy(q.astype(np.float32)), samples=2)
        pts, mask = pts.reshape(6, 15, 2, 3), mask.reshape(6, 15, 2)[0, :, 0]
        assert int(mask.sum()) == c.p0.shape[1]  # one core per link that carries geometry
        np.testing.assert_allclose(pts[:, mask, 0].numpy(), c.p0, atol=1e-6)
        np.testing.assert_allclose(pts[:, mask, 1].numpy(), c.p1, atol=1e-6)
        np.testing.assert_allclose(r[0].numpy(), c.radius[0], rtol=1e-6)


def test_joints_beyond_the_limits_are_clamped_before_the_kinematics(caps):
    hm = HandModel.from_params(get_hand("barrett_hand"))
    q = np.clip(hm.random_configurations(2, seed=0) + 3.0, hm.lower, hm.upper)
    inside = caps.points(torch.ones(2, dtype=torch.long), torch.from_numpy(q.astype(np.float32)))[0]
    beyond = caps.points(torch.ones(2, dtype=torch.long), torch.from_numpy((q + 3.0 * (hm.upper > hm.lower)).astype(np.float32)))[0]
    torch.testing.assert_close(inside, beyond)


def test_non_base_hands_are_refused_by_name():
    with pytest.raises(GraspConfigError, match="base-form.*leap_3303"):
        FingerCapsules([get_hand("leap_3303")], ["leap_3303"])


@pytest.mark.parametrize("name", ["capsule", "box", "sphere"])
def test_the_grid_signed_distance_is_the_objects_within_a_millimetre(name):
    obj = ObjectModel.builtin(name)
    grid = SDFGrids.from_objects([obj], resolution=48)
    lo, hi = np.asarray(obj.mesh.bounds)
    p = np.random.default_rng(0).uniform(lo - 0.01, hi + 0.01, (3000, 3))
    got = grid(torch.zeros(len(p), dtype=torch.long), torch.from_numpy(p.astype(np.float32))).numpy()
    exact = obj.signed_distance(p)
    near = np.abs(exact) < 0.01  # where the term acts
    assert np.abs(got - exact)[near].max() < 1e-3
    assert np.all(np.sign(got[np.abs(exact) > 2e-3]) == np.sign(exact[np.abs(exact) > 2e-3]))
    # beyond the grid the lookup clamps to its edge: outside stays outside
    far = grid(torch.zeros(1, dtype=torch.long), torch.tensor([[1.0, 1.0, 1.0]]))
    assert float(far) > 0.01


def _sunk_grasp(hand: str, obj: ObjectModel, depth: float) -> np.ndarray:
    """One grasp of ``hand``: fingers a third of the way into their ranges (bent, so that flexing moves a
    sunk point out of the object rather than along its surface), palm facing the object's +x side,
    moved along x until the deepest finger point is ``depth`` [m] inside (negative: outside), by the
    exact signed distance."""
    hm = HandModel.from_params(get_hand(hand))
    q = hm.lower + (hm.upper - hm.lower) / 3.0
    R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # palm normal (+z) towards -x
    g = np.concatenate([[0.3, 0.0, 0.0], matrix_to_rot6d(R[None])[0], q])
    for _ in range(30):  # the clearance is not linear in x near edges: iterate
        err = finger_clearance(hm, obj, g[None])[0] + depth
        if abs(err) < 2e-5:
            return g
        g[0] -= err
    raise AssertionError("could not place the grasp")


def _term(caps, grid, hand_i, g):
    T, q = grasp_to_pose(g[None])
    f = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    return penetration(caps, grid, torch.tensor([hand_i]), torch.tensor([0]), f(q), f(T[:, :3, 3]), f(T[:, :3, :3]))


def test_the_term_is_zero_clear_of_the_object_and_grows_with_depth(caps):
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    values = []
    for depth in (-0.005, 0.0005, 0.003, 0.006):  # 5 mm clear, within the 1 mm clearance, 3 and 6 mm in
        g = _sunk_grasp("allegro_hand_left", obj, depth)
        P, deepest = _term(caps, grid, 0, g)
        assert float(deepest) == pytest.approx(-depth, abs=1e-3)
        values.append(float(P))
    assert values[0] == 0.0 and values[1] == 0.0
    assert 0.0 < values[2] < values[3]
    # a point 3 mm deep, 2 mm past the clearance: (0.2 cm)^2 from that point alone
    assert values[2] >= 0.04 * 0.9


def test_descending_the_terms_gradient_lifts_sunk_fingers(caps):
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    g = _sunk_grasp("shadow_hand_right", obj, 0.004)
    T, q = grasp_to_pose(g[None])
    f = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    qt = f(q).requires_grad_(True)
    P0, _ = penetration(caps, grid, torch.tensor([2]), torch.tensor([0]), qt, f(T[:, :3, 3]), f(T[:, :3, :3]))
    P0.backward()
    assert torch.any(qt.grad != 0)
    step = qt.detach() - 0.05 * qt.grad / qt.grad.norm()
    P1, _ = penetration(caps, grid, torch.tensor([2]), torch.tensor([0]), step, f(T[:, :3, 3]), f(T[:, :3, :3]))
    assert float(P1) < float(P0.detach())


def test_off_by_default_and_on_it_trains_logs_and_resumes(dataset, tmp_path):
    off = train_grasp(dataset, tiny_model_config(), tiny_train_config(log_every=1), progress=False)
    assert "penetration" not in off.metrics["history"][-1]
    on = train_grasp(dataset, tiny_model_config(), tiny_train_config(penetration_weight=0.05, log_every=1), tmp_path / "on",
                     progress=False)
    h = on.metrics["history"]
    assert all(np.isfinite(e["penetration"]) for e in h) and "penetration" in on.metrics["final_losses"]
    # the term enters the total with its weight
    assert all(e["total"] == pytest.approx(e["diffusion"] + e["joints"] + 0.05 * e["penetration"], rel=1e-5) for e in h)
    # the diffusion loss sees the same batches and noise with and without the term (at the first step,
    # before any update)
    assert h[0]["diffusion"] == pytest.approx(off.metrics["history"][0]["diffusion"], rel=1e-6)
    shifted = train_grasp(dataset, tiny_model_config(), tiny_train_config(penetration_weight=0.05, penetration_shift=0.01, log_every=1),
                          progress=False)
    assert shifted.metrics["history"][0]["penetration"] != h[0]["penetration"]
    with pytest.raises(CheckpointError, match="penetration_weight"):
        train_grasp(dataset, tiny_model_config(), tiny_train_config(penetration_weight=0.1, log_every=1), tmp_path / "on", resume=True,
                    progress=False)
    more = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=8, penetration_weight=0.05, log_every=1), tmp_path / "on",
                       resume=True, progress=False)
    assert more.metrics["history"][-1]["step"] == 8 and "penetration" in more.metrics["history"][-1]


def test_a_checkpoint_made_before_the_option_existed_resumes(dataset, tmp_path):
    run = tmp_path / "old"
    train_grasp(dataset, tiny_model_config(), tiny_train_config(), run, progress=False)
    ckpt_path = run / "checkpoints" / "last.pt"
    ckpt = torch.load(ckpt_path, weights_only=False)
    for k in ("penetration_weight", "penetration_shift"):
        del ckpt["spec"]["train"][k]
    torch.save(ckpt, ckpt_path)
    res = train_grasp(dataset, tiny_model_config(), tiny_train_config(steps=8), run, resume=True, progress=False)
    assert res.metrics["history"][-1]["step"] == 8
    assert json.loads((run / "config.json").read_text())["train"]["penetration_weight"] == 0.0


@pytest.mark.parametrize("kw", [{"penetration_weight": -0.1}, {"penetration_shift": -0.001}, {"contact_weight": -0.1}])
def test_negative_settings_are_refused(kw):
    with pytest.raises(GraspConfigError, match=next(iter(kw))):
        tiny_train_config(**kw)


def test_cli_takes_the_term_and_refuses_hands_it_cannot_model(dataset, tmp_path, capsys):
    import importlib

    cli = importlib.import_module("ohra.cli.main").main
    run = tmp_path / "run"
    assert cli(["train", "grasp", "--data", str(dataset), "--steps", "2", "--batch-size", "8", "--penetration-weight", "0.05",
                "--penetration-shift", "0.005", "-o", str(run), "--quiet"]) == 0
    train = json.loads((run / "config.json").read_text())["train"]
    assert (train["penetration_weight"], train["penetration_shift"]) == (0.05, 0.005)
    assert "penetration" in json.loads((run / "metrics.json").read_text())["final_losses"]
    leap = write_dataset(tmp_path / "leap", hands=("leap_3303",), objects=("box",))
    capsys.readouterr()
    assert cli(["train", "grasp", "--data", str(leap), "--condition", "params", "--steps", "1", "--batch-size", "4",
                "--penetration-weight", "0.05", "-o", str(tmp_path / "r2"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "base-form" in err and "leap_3303" in err and "Traceback" not in err


def test_the_shifted_palm_is_the_one_the_joint_network_sees(dataset, monkeypatch):
    """The shift is drawn in the object frame; the network's input translation is in the batch's rotated
    frame, normalised: both must describe the same palm."""
    import ohra.learn.grasp.train as train_mod
    from ohra.learn.grasp.data import TrainingData, make_batch
    from ohra.learn.grasp.model import GraspNet

    cfg = tiny_train_config(penetration_weight=0.05, penetration_shift=0.01, batch_size=8)
    td = TrainingData.load(dataset, cfg)
    hand = torch.zeros(len(td.hands), 4)
    present = torch.from_numpy(np.stack([p.present_joints for p in td.params]))
    batch = make_batch(td, cfg, 64, 0, hand, present, 0.1)
    term = train_mod.ContactTerm.for_data(td, cfg, 0.1)
    net = GraspNet(tiny_model_config(), 4)
    seen = {}
    monkeypatch.setattr(net.joints, "forward", lambda x: (seen.setdefault("t_in", x[:, -3:]), torch.zeros(len(x), 22))[1])
    monkeypatch.setattr(train_mod, "penetration", lambda *a: seen.setdefault("args", a) and (torch.tensor(0.0), None))
    feats = torch.zeros(len(batch.q), net.cfg.object_dim)
    term(net, feats, batch)
    t_obj = seen["args"][5]
    moved = t_obj - batch.t_obj
    assert 0.002 < float(moved.norm(dim=1).mean()) < 0.05  # shifted by about the std
    in_rotated = torch.einsum("bij,bj->bi", batch.R_cloud, t_obj) / 0.1
    torch.testing.assert_close(seen["t_in"], in_rotated, atol=1e-5, rtol=1e-5)


def _gap(caps, grid, hand_i, data_g, palm_dx, q=None, form="capped"):
    """C for the data grasp ``data_g`` against a prediction with joints ``q`` (default: the data's) and
    the palm moved by ``palm_dx`` [m] along x (+: away from the object, whose +x face the palm faces)."""
    T, qd = grasp_to_pose(data_g[None])
    f = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    t = f(T[:, :3, 3])
    q = f(qd) if q is None else q
    return contact_gap(caps, grid, torch.tensor([hand_i]), torch.tensor([0]), q, t + torch.tensor([[palm_dx, 0.0, 0.0]]),
                       f(qd), t, f(T[:, :3, :3]), form=form)


def test_the_contact_term_is_zero_at_the_datas_fingers_and_two_sided_around_them(caps):
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    touching = _sunk_grasp("allegro_hand_left", obj, 0.0)
    assert float(_gap(caps, grid, 0, touching, 0.0)) == 0.0
    hover, sunk = float(_gap(caps, grid, 0, touching, 0.003)), float(_gap(caps, grid, 0, touching, -0.003))
    # the deepest link moves by the full 3 mm either way: (0.3 cm)^2 from it alone, near-linear in the shift
    assert hover >= 0.09 * 0.9 and sunk >= 0.09 * 0.9
    assert float(_gap(caps, grid, 0, touching, 0.006)) > 3 * hover
    d, mask = link_distances(caps, grid, torch.tensor([0]), torch.tensor([0]), *[
        torch.from_numpy(np.asarray(a, dtype=np.float32)) for a in (grasp_to_pose(touching[None])[1],
                                                                      grasp_to_pose(touching[None])[0][:, :3, 3],
                                                                      grasp_to_pose(touching[None])[0][:, :3, :3])])
    assert float(d[mask].min()) == pytest.approx(0.0, abs=1e-3) and torch.isinf(d[~mask]).all()


def test_links_clear_of_the_object_in_both_do_not_count(caps):
    """Beyond ``reach`` (1 cm) clear is clear: the data 2 cm off, a prediction whose nearest link is 1.7 cm
    off costs nothing, one whose nearest link is 1.1 cm off neither, one 0.5 cm off (within reach) does
    (the palm moves 5 / 12 / 18 mm; the bent fingers' nearest points approach the box's edge slower)."""
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    far = _sunk_grasp("allegro_hand_left", obj, -0.02)
    assert float(_gap(caps, grid, 0, far, -0.005)) == 0.0
    assert float(_gap(caps, grid, 0, far, -0.012)) == 0.0
    assert float(_gap(caps, grid, 0, far, -0.018)) > 0.0


@pytest.mark.parametrize("palm_dx", [0.004, -0.004])
def test_descending_the_contact_terms_gradient_moves_fingers_back_to_the_datas_contact(caps, palm_dx):
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    touching = _sunk_grasp("shadow_hand_right", obj, 0.0)
    qt = torch.from_numpy(grasp_to_pose(touching[None])[1].astype(np.float32)).requires_grad_(True)
    C0 = _gap(caps, grid, 2, touching, palm_dx, qt)
    C0.backward()
    step = qt.detach() - 0.02 * qt.grad / qt.grad.norm()
    assert float(_gap(caps, grid, 2, touching, palm_dx, step)) < float(C0.detach())


def test_the_contact_option_trains_logs_and_enters_the_total_with_its_weight(dataset, tmp_path):
    off = train_grasp(dataset, tiny_model_config(), tiny_train_config(log_every=1), progress=False)
    on = train_grasp(dataset, tiny_model_config(), tiny_train_config(contact_weight=0.2, log_every=1), progress=False)
    h = on.metrics["history"]
    assert "contact" not in off.metrics["history"][-1] and "penetration" not in h[-1]
    assert all(np.isfinite(e["contact"]) and e["contact"] > 0 for e in h)
    assert all(e["total"] == pytest.approx(e["diffusion"] + e["joints"] + 0.2 * e["contact"], rel=1e-5) for e in h)
    assert h[0]["diffusion"] == pytest.approx(off.metrics["history"][0]["diffusion"], rel=1e-6)
    both = train_grasp(dataset, tiny_model_config(), tiny_train_config(contact_weight=0.2, penetration_weight=0.05, log_every=1),
                       progress=False)
    e = both.metrics["history"][0]
    assert e["total"] == pytest.approx(e["diffusion"] + e["joints"] + 0.05 * e["penetration"] + 0.2 * e["contact"], rel=1e-5)


def test_cli_takes_the_contact_weight(dataset, tmp_path):
    import importlib

    cli = importlib.import_module("ohra.cli.main").main
    run = tmp_path / "run"
    assert cli(["train", "grasp", "--data", str(dataset), "--steps", "2", "--batch-size", "8", "--contact-weight", "0.3",
                "-o", str(run), "--quiet"]) == 0
    assert json.loads((run / "config.json").read_text())["train"]["contact_weight"] == 0.3
    assert "contact" in json.loads((run / "metrics.json").read_text())["final_losses"]


def test_the_target_form_pulls_a_touching_link_back_from_beyond_reach(caps):
    """The data touch; the prediction's palm is 2 cm out, every link beyond the 1 cm reach: the capped
    form is flat there (no gradient), the target form costs the whole distance and its descent closes
    the fingers. Where the data's links are clear beyond reach the two forms agree."""
    obj = ObjectModel.builtin("box")
    grid = SDFGrids.from_objects([obj])
    touching = _sunk_grasp("shadow_hand_right", obj, 0.0)
    q0 = torch.from_numpy(grasp_to_pose(touching[None])[1].astype(np.float32))
    qc, qt = q0.clone().requires_grad_(True), q0.clone().requires_grad_(True)
    capped = _gap(caps, grid, 2, touching, 0.02, qc)
    target = _gap(caps, grid, 2, touching, 0.02, qt, form="target")
    capped.backward()
    target.backward()
    assert torch.all(qc.grad == 0) and float(target.detach()) > float(capped.detach()) > 0
    step = qt.detach() - 0.02 * qt.grad / qt.grad.norm()
    assert float(_gap(caps, grid, 2, touching, 0.02, step, form="target")) < float(target.detach())
    far = _sunk_grasp("allegro_hand_left", obj, -0.02)
    for dx in (-0.005, -0.018):
        assert float(_gap(caps, grid, 0, far, dx, form="target")) == pytest.approx(float(_gap(caps, grid, 0, far, dx)))


def test_the_contact_form_is_a_checked_setting(dataset, tmp_path):
    import importlib

    with pytest.raises(GraspConfigError, match="contact_form"):
        tiny_train_config(contact_form="both")
    cli = importlib.import_module("ohra.cli.main").main
    run = tmp_path / "run"
    assert cli(["train", "grasp", "--data", str(dataset), "--steps", "2", "--batch-size", "8", "--contact-weight", "0.3",
                "--contact-form", "target", "-o", str(run), "--quiet"]) == 0
    assert json.loads((run / "config.json").read_text())["train"]["contact_form"] == "target"
