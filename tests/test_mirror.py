"""Mirror images of hands and grasps (``ohra.canonical.mirror``) and the grasp model's ``mirror=`` option:
a mirrored hand at mirrored joint angles is the reflected hand, link by link; a mirrored grasp on the
mirrored object touches the object where the reflected grasp does; a model samples a hand as its mirror
image exactly as it samples that image on the mirrored object; in simulation a mirrored grasp on a
mirror-symmetric object has the same outcome as the grasp."""

from __future__ import annotations

import numpy as np
import pytest

from ohra.canonical import HandModel
from ohra.canonical.mirror import BASE_FLIPPED_JOINTS, PALM_MIRROR, mirror_grasps, mirror_params
from ohra.canonical.params import BaseParams, ExtendedParams
from ohra.errors import GraspError, ParamsError
from ohra.hands import get_hand
from ohra.hands.leap.variants import variant_names
from ohra.hands.registry import registered_hands
from ohra.rotations import rot6d_to_matrix

H = np.eye(4)
H[:3, :3] = PALM_MIRROR


def _forms(name: str) -> list:
    p = get_hand(name)
    return [p, p.to_extended()] if isinstance(p, BaseParams) else [p]


def _assert_reflected(params, seed: int = 0, n: int = 16) -> None:
    """Every frame of the mirror image at ``signs * q`` is ``M T M`` of the hand's at ``q``."""
    image = mirror_params(params)
    a, b = HandModel.from_params(params), HandModel.from_params(image.params)
    assert a.frame_names == b.frame_names
    lo, up = np.asarray(params.joint_lowers), np.asarray(params.joint_uppers)
    q = np.random.default_rng(seed).uniform(lo, up, (n, 22))
    qm = image.joints(q)
    # the mirrored angles lie within the image's limits
    assert np.all(qm >= np.asarray(image.params.joint_lowers) - 1e-12) and np.all(qm <= np.asarray(image.params.joint_uppers) + 1e-12)
    np.testing.assert_allclose(b.frame_poses(qm), np.einsum("ij,nfjk,kl->nfil", H, a.frame_poses(q), H), atol=1e-12)


REGISTERED = ("allegro_hand_left", "allegro_hand_right", "barrett_hand", "dex3_left", "dex3_right", "gaia_hand_left",
              "gaia_hand_right", "inspire_hand_left", "inspire_hand_right", "leap_hand_left", "leap_hand_right", "mano",
              "shadow_hand_left", "shadow_hand_right", "sharpa_wave_left", "sharpa_wave_right")


def test_the_hand_list_is_the_registry():
    assert sorted(REGISTERED) == sorted(registered_hands())


@pytest.mark.parametrize("name", REGISTERED)
def test_a_mirror_image_at_mirrored_angles_is_the_reflected_hand_for_every_registered_hand(name):
    for params in _forms(name):
        _assert_reflected(params)


def test_mirror_images_of_every_leap_variant_and_of_sampled_hands_are_exact():
    from ohra.learn.sampler import sample_params

    for name in variant_names()[::5]:  # 52 of the 256 variants: every digit appears in every place
        _assert_reflected(get_hand(name), n=4)
    for k, params in enumerate(sample_params(12, seed=3)):
        _assert_reflected(params, seed=k, n=4)
        _assert_reflected(params.to_extended(), seed=k, n=4)


def test_mirroring_twice_gives_the_hand_back_and_turns_its_handedness():
    for name in ("shadow_hand_right", "allegro_hand_left", "leap_3303", "inspire_hand_right"):
        for params in _forms(name):
            image = mirror_params(params)
            assert type(image.params) is type(params)
            assert getattr(image.params, "template", None) == getattr(params, "template", None)
            assert image.params.handedness != params.handedness
            assert mirror_params(image.params).params == params
            np.testing.assert_array_equal(mirror_params(image.params).signs, image.signs)


def test_the_mirror_image_of_a_right_hand_reads_like_its_parsed_left_twin():
    """The registered Shadow pair is a near-exact mirror pair (each hand parsed from its own URDF): the right
    hand's mirror image lies within 0.06 of the parsed left hand in every number (metres, radians, axis
    components; the largest gaps are the little metacarpal's frame angles, fitted on each hand apart), in
    both forms; the abduction joints turn the other way; fingertips agree within 3 mm."""
    for form in ("base", "extended"):
        right, left = (get_hand(f"shadow_hand_{s}") for s in ("right", "left"))
        if form == "extended":
            right, left = right.to_extended(), left.to_extended()
        image = mirror_params(right)
        assert np.abs(image.params.to_vector() - left.to_vector()).max() < 0.06
        np.testing.assert_array_equal(np.flatnonzero(image.signs < 0), BASE_FLIPPED_JOINTS)
        q = np.random.default_rng(0).uniform(right.joint_lowers, right.joint_uppers, (8, 22))
        tips_left = HandModel.from_params(left).fingertips(image.joints(q))
        tips_image = HandModel.from_params(image.params).fingertips(image.joints(q))
        assert np.abs(tips_left - tips_image).max() < 0.003  # m


def test_mirror_params_refuses_what_is_not_params():
    with pytest.raises(ParamsError, match="BaseParams or ExtendedParams"):
        mirror_params({"palm_radius": 0.05})


# -- grasps ---------------------------------------------------------------------------------------
def _world_capsules(params, grasp: np.ndarray) -> np.ndarray:
    """(K, 2, 3) capsule end points of the hand at ``grasp`` in the object frame."""
    caps = HandModel.from_params(params).capsules(grasp[9:])
    R, t = rot6d_to_matrix(grasp[3:9][None])[0], grasp[:3]
    return np.stack([caps.p0 @ R.T + t, caps.p1 @ R.T + t], axis=1)


@pytest.mark.parametrize("name", ["shadow_hand_right", "barrett_hand", "leap_3033"])
def test_a_mirrored_grasp_places_the_mirror_image_where_the_reflected_hand_would_be(name):
    params = get_hand(name)
    image = mirror_params(params)
    rng = np.random.default_rng(1)
    from scipy.spatial.transform import Rotation

    for k in range(5):
        R = Rotation.random(random_state=k).as_matrix()
        q = rng.uniform(params.joint_lowers, params.joint_uppers)
        g = np.concatenate([rng.normal(scale=0.05, size=3), R[:, 0], R[:, 1], q])
        gm = mirror_grasps(g, image.signs)
        Rm = rot6d_to_matrix(gm[3:9][None])[0]
        assert np.linalg.det(Rm) == pytest.approx(1.0)  # a rotation, not a reflection
        expected = _world_capsules(params, g) * [1.0, -1.0, 1.0]
        np.testing.assert_allclose(_world_capsules(image.params, gm), expected, atol=1e-12)
        np.testing.assert_array_equal(mirror_grasps(gm, image.signs), g)  # its own inverse


def test_mirror_grasps_refuses_wrong_shapes():
    with pytest.raises(GraspError, match=r"\(31,\) or \(n, 31\)"):
        mirror_grasps(np.zeros((2, 30)), np.ones(22))
    with pytest.raises(GraspError, match="22 joint signs"):
        mirror_grasps(np.zeros(31), np.ones(21))


# -- the grasp model ------------------------------------------------------------------------------
torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    from grasp_fixtures import tiny_model_config, tiny_train_config, write_dataset

    from ohra.learn.grasp.train import train_grasp

    data = write_dataset(tmp_path_factory.mktemp("grasps"), hands=("shadow_hand_right", "barrett_hand"))
    return {c: train_grasp(data, tiny_model_config(condition=c), tiny_train_config(), progress=False).model
            for c in ("vae", "params")}


def _mirrored_object(obj):
    import trimesh

    from ohra.objects.model import ObjectModel

    mesh = obj.mesh.copy()
    mesh.apply_transform(H)
    return ObjectModel(mesh, obj.name + "-mirrored")


@pytest.mark.parametrize("condition", ["vae", "params"])
def test_sampling_as_the_mirror_image_is_sampling_the_image_on_the_mirrored_object(models, condition):
    """``mirror=True`` for a hand = the model sampling the hand's mirror image on the mirrored object (its
    surface points exactly reflected), with the reflected wrist rotations, then mirrored back."""
    from scipy.spatial.transform import Rotation

    from ohra.objects.model import ObjectModel

    model = models[condition]
    hand = get_hand("shadow_hand_left")
    image = mirror_params(hand)
    obj = ObjectModel.procedural("superquadric", 7)  # no symmetry to hide a wrong reflection
    twin = _mirrored_object(obj)
    model._clouds[twin.mesh_hash] = model.object_cloud(obj) * torch.tensor([1.0, -1.0, 1.0])
    R = Rotation.random(6, random_state=4).as_matrix()
    got = model.sample(hand, obj, 6, rotations=R, seed=5, mirror=True)
    np.testing.assert_allclose(got[:, 3:6], R[:, :, 0], atol=1e-12)  # the wrist rotations asked for
    np.testing.assert_allclose(got[:, 6:9], R[:, :, 1], atol=1e-12)
    Rm = PALM_MIRROR @ R @ PALM_MIRROR
    direct = model.sample(image.params, twin, 6, rotations=Rm, seed=5, mirror=False)
    np.testing.assert_allclose(got, mirror_grasps(direct, image.signs), atol=1e-6)
    assert np.all(got[:, 9:] >= hand.joint_lowers) and np.all(got[:, 9:] <= hand.joint_uppers)
    assert not np.allclose(got, model.sample(hand, obj, 6, rotations=R, seed=5, mirror=False))


@pytest.mark.e2e  # nine six-direction tests (~9 s)
def test_in_simulation_robust_grasps_mirrored_hold_with_the_mirror_image_and_not_with_the_hand():
    """Physics is mirror-symmetric: robust grasps of the committed data (they hold under small perturbations;
    single outcomes of marginal grasps flip under a microradian, so only robust ones can be compared) on
    procedural objects (symmetric through their x-z planes) still hold when hand and grasp are mirrored;
    the mirrored grasps given to the unmirrored hand do not."""
    import sys
    from pathlib import Path

    from ohra.data import GraspDataset
    from ohra.objects.model import ObjectModel
    from ohra.sim import GraspEvaluator, SimHand

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "benchmarks"))
    from grasp_study import data_protocol

    data = root / "datasets" / "grasp_unified_s0"
    protocol = data_protocol([str(data)])
    ds = GraspDataset([data], hands=["shadow_hand_right"])
    right = get_hand("shadow_hand_right")
    image = mirror_params(right)
    picked = []
    for hand, name in ds.pairs:
        family = name.split("-")[0]
        if family in ("cylinder", "ellipsoid", "box") and len(picked) < 3:
            g = ds.load_shard(hand, name)["grasps"]
            if len(g):
                picked.append((ObjectModel.procedural(family, int(name.split("-")[1])), g[:1].astype(float)))
    assert len(picked) == 3
    for obj, g in picked:
        with GraspEvaluator(SimHand.from_params(right, name="right"), obj, protocol) as ev:
            assert ev.evaluate(g).success.all()
            assert not ev.evaluate(mirror_grasps(g, image.signs)).success.any()  # control: the wrong hand drops it
        with GraspEvaluator(SimHand.from_params(image.params, name="image"), obj, protocol) as ev:
            assert ev.evaluate(mirror_grasps(g, image.signs)).success.all()


def test_auto_mirrors_a_hand_whose_mirror_image_is_nearer_the_training_hands(models):
    for model in models.values():
        assert not model.mirrors("shadow_hand_right") and not model.mirrors("barrett_hand")  # trained on
        assert model.mirrors("shadow_hand_left")  # the left twin of a training hand
        assert model.mirrors("shadow_hand_left", False) is False and model.mirrors("shadow_hand_right", True) is True
        with pytest.raises(GraspError, match="mirror: expected True, False or 'auto'"):
            model.mirrors("shadow_hand_left", "yes")
    # auto = the decision: the default sample of a left hand is the mirrored one, of a training hand the plain one
    m = models["params"]
    np.testing.assert_array_equal(m.sample("shadow_hand_left", "builtin:capsule", 3, seed=1),
                                  m.sample("shadow_hand_left", "builtin:capsule", 3, seed=1, mirror=True))
    np.testing.assert_array_equal(m.sample("shadow_hand_right", "builtin:capsule", 3, seed=1),
                                  m.sample("shadow_hand_right", "builtin:capsule", 3, seed=1, mirror=False))


def test_auto_never_mirrors_when_no_training_hand_resolves(models):
    import copy

    m = copy.copy(models["params"])
    # a model saved before training recorded its hands' conditions, whose hands no longer resolve by name
    m.meta = {**{k: v for k, v in m.meta.items() if k != "train_conditions"}, "hands": ["/gone/hand.json"]}
    m._cache = {}
    assert not m.mirrors("shadow_hand_left")
    # a model that recorded them mirrors by them, whatever its hands were called
    m.meta, m._cache = {**models["params"].meta, "hands": ["/gone/hand.json"]}, {}
    assert m.mirrors("shadow_hand_left")  # trained on shadow_hand_right


def test_the_shipped_models_mirror_left_twins_of_their_training_hands():
    from ohra.learn.grasp.model import load_grasp_model

    default = load_grasp_model()
    for h in ("allegro_hand_left", "barrett_hand", "shadow_hand_right"):
        assert not default.mirrors(h)
    assert default.mirrors("shadow_hand_left") and default.mirrors("allegro_hand_right")
    leap = load_grasp_model("leap")
    assert not leap.mirrors("leap_3303") and leap.mirrors(mirror_params(get_hand("leap_3303")).params)


def test_evaluation_records_mirrored_pairs_and_keeps_them_apart_when_resumed(models, tmp_path):
    from ohra.learn.grasp.evaluate import evaluate_model

    m = models["params"]
    kw = dict(n=2, seed=0, protocol="reference", resume_dir=tmp_path)
    on = evaluate_model(m, ["shadow_hand_left"], ["builtin:capsule"], mirror="auto", **kw)
    assert on.pairs[0].mirrored and on.meta["mirrored_hands"] == ["shadow_hand_left"]
    off = evaluate_model(m, ["shadow_hand_left"], ["builtin:capsule"], mirror=False, **kw)
    assert not off.pairs[0].mirrored and off.meta["resumed_pairs"] == 0  # not the mirrored pair stored above
    assert not np.allclose(on.pairs[0].grasps, off.pairs[0].grasps)
    again = evaluate_model(m, ["shadow_hand_left"], ["builtin:capsule"], mirror=True, **kw)
    assert again.meta["resumed_pairs"] == 1 and again.pairs[0].mirrored
    np.testing.assert_array_equal(again.pairs[0].grasps, on.pairs[0].grasps)


def test_cli_sample_mirror_flag_and_record(tmp_path, capsys):
    from ohra.cli.main import main

    assert main(["grasp", "sample", "--hand", "shadow_hand_left", "--object", "builtin:capsule", "-n", "3",
                 "-o", str(tmp_path / "a.npz")]) == 0
    assert "sampled as its mirror image" in capsys.readouterr().out
    with np.load(tmp_path / "a.npz") as d:
        assert bool(d["mirrored"]) and d["grasps"].shape == (3, 31)
    assert main(["grasp", "sample", "--hand", "shadow_hand_left", "--object", "builtin:capsule", "-n", "3", "--mirror", "off",
                 "-o", str(tmp_path / "b.npz")]) == 0
    assert "mirror image" not in capsys.readouterr().out
    with np.load(tmp_path / "b.npz") as d:
        assert not bool(d["mirrored"])


def test_a_mirrored_sample_follows_a_mesh_whose_origin_lies_beside_it_with_centre_and_candidates(models):
    """``centre=True`` and ``candidates=K`` work on the mirrored path too: moving the mesh's origin only moves
    the grasps, and the kept draw lies in the hand's own limits."""
    import trimesh

    from ohra.objects.model import ObjectModel

    def box(shift):
        mesh = trimesh.creation.box(extents=(0.05, 0.07, 0.09))
        mesh.apply_translation(shift)
        return ObjectModel(mesh, "box")

    m = models["vae"]
    shift = np.array([0.15, -0.02, 0.04])
    for k in (1, 3):
        at_origin = m.sample("shadow_hand_left", box((0, 0, 0)), 6, seed=3, mirror=True, candidates=k)
        moved = m.sample("shadow_hand_left", box(shift), 6, seed=3, centre=True, mirror=True, candidates=k)
        np.testing.assert_allclose(moved[:, :3] - shift, at_origin[:, :3], atol=1e-6)
        np.testing.assert_allclose(moved[:, 3:], at_origin[:, 3:], atol=1e-6)


def test_bad_signs_and_joint_angles_are_grasp_errors_naming_the_problem():
    image = mirror_params(get_hand("shadow_hand_right"))
    with pytest.raises(GraspError, match="numeric grasps and signs"):
        mirror_grasps("abc", image.signs)
    with pytest.raises(GraspError, match=r"signs\[0\] = 0"):
        mirror_grasps(np.zeros(31), np.zeros(22))
    with pytest.raises(GraspError, match=r"signs\[3\] = 2"):
        mirror_grasps(np.zeros(31), np.r_[1.0, -1.0, 1.0, 2.0, np.ones(18)])
    with pytest.raises(GraspError, match=r"expected shape \(22,\) or \(\.\.\., 22\), got \(5,\)"):
        image.joints(np.zeros(5))


def test_mirror_takes_the_recorded_numpy_bool_and_keeps_the_hint_for_hands_without_base_form(models, tmp_path):
    m = models["vae"]
    assert m.mirrors("shadow_hand_right", np.True_) is True and m.mirrors("shadow_hand_left", np.array(False)) is False
    for mirror in (False, True, "auto"):  # the same way out is named whatever the mirror setting
        with pytest.raises(ParamsError, match="condition='params' can use such hands"):
            m.sample("leap_3303", "builtin:capsule", 2, mirror=mirror)


@pytest.mark.e2e  # five `ohra eval` runs on Shadow (~11 s): in .ci/run's e2e set, keeping the default suite under 5 min
def test_ohra_eval_notes_grasps_sampled_for_another_hand(tmp_path, capsys):
    from ohra.cli.main import main

    f = tmp_path / "left.npz"
    assert main(["grasp", "sample", "--hand", "shadow_hand_left", "--object", "builtin:box", "-n", "2", "-o", str(f)]) == 0
    capsys.readouterr()
    assert main(["eval", str(f), "--hand", "shadow_hand_right", "--object", "builtin:box", "--quiet"]) == 0
    assert f"{f} was sampled for shadow_hand_left; evaluating it on --hand shadow_hand_right" in capsys.readouterr().err
    assert main(["eval", str(f), "--hand", "shadow_hand_left", "--object", "builtin:box", "--quiet"]) == 0
    assert "was sampled for" not in capsys.readouterr().err
    # the same hand as a params file: silent in the form the grasps were made for, a note naming the form otherwise
    from ohra.hands import get_hand

    for form in ("base", "extended"):
        get_hand("shadow_hand_left", form).to_json(tmp_path / form / "shadow_hand_left.json")
    assert main(["eval", str(f), "--hand", str(tmp_path / "base" / "shadow_hand_left.json"), "--object", "builtin:box", "--quiet"]) == 0
    assert "was sampled for" not in capsys.readouterr().err
    ext = tmp_path / "extended" / "shadow_hand_left.json"
    assert main(["eval", str(f), "--hand", str(ext), "--object", "builtin:box", "--quiet"]) == 0
    assert (f"{f} was sampled for the base form of shadow_hand_left; --hand {ext} gives its extended form, evaluated as given "
            "(--hand shadow_hand_left --form base evaluates") in capsys.readouterr().err


def test_couplings_of_the_mirror_image_hold_at_the_mirrored_angles():
    from ohra.canonical.couplings import Coupling, project, residual
    from ohra.canonical.mirror import mirror_couplings
    from ohra.hands import get_couplings

    params = get_hand("inspire_hand_right")
    image = mirror_params(params)
    # the registered mimic couplings (flexion: same sign) and two across reversed joints, with offsets
    cs = tuple(get_couplings("inspire_hand_right")) + (Coupling("index_joint1", "thumb_joint3", 0.5, 0.1),
                                                       Coupling("middle_joint1", "index_joint2", -2.0, 0.2))
    q = project(cs, np.random.default_rng(0).uniform(-1, 1, (5, 22)))
    assert np.abs(residual(cs, q)).max() < 1e-12
    mirrored = mirror_couplings(cs, image.signs)
    assert np.abs(residual(mirrored, image.joints(q))).max() < 1e-12
    assert np.abs(residual(cs, image.joints(q))).max() > 0.1  # the unmirrored couplings do not hold there


def test_cli_hand_mirror_writes_the_image_with_its_couplings_and_mirrors_back(tmp_path, capsys):
    from ohra.canonical.couplings import read_couplings
    from ohra.canonical.mirror import mirror_couplings
    from ohra.canonical.params import load_params
    from ohra.cli.main import main
    from ohra.hands import get_couplings

    out = tmp_path / "inspire_left.json"
    assert main(["hand", "mirror", "inspire_hand_right", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "the mirror image of inspire_hand_right (right -> left hand)" in err
    image = mirror_params(get_hand("inspire_hand_right"))
    assert load_params(out) == image.params
    assert read_couplings(out) == mirror_couplings(get_couplings("inspire_hand_right"), image.signs)
    back = tmp_path / "back.json"
    assert main(["hand", "mirror", str(out), "-o", str(back)]) == 0
    assert load_params(back).isclose(get_hand("inspire_hand_right"), atol=1e-12)
    assert main(["hand", "mirror", "shadow_hand_right"]) == 0  # to stdout; the reversed joints named on stderr
    cap = capsys.readouterr()
    assert load_params(cap.out) == image.params.__class__.from_dict(mirror_params(get_hand("shadow_hand_right")).params.to_dict())
    assert "index_joint1" in cap.err and "thumb_joint3" in cap.err
    assert main(["hand", "mirror", "no_such_hand"]) == 2
