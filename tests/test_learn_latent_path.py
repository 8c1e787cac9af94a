"""Latent paths of the morphology VAE: the geodesic interpolation against the straight line."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import ohra  # noqa: E402
from ohra.canonical.kinematics import HandModel  # noqa: E402
from ohra.canonical.params import BaseParams  # noqa: E402
from ohra.learn import geometry as geo  # noqa: E402
from ohra.learn.fk_torch import tips  # noqa: E402
from ohra.learn.latent_path import (  # noqa: E402
    THUMB_BOX_MARGIN_M, _tips_q0, arc_length_resample, structure_changes, thumb_box, thumb_excursion, tip_moves,
)
from ohra.learn.morph import load_vae  # noqa: E402
from ohra.learn.vae import GeometryLoss  # noqa: E402


@pytest.fixture(scope="module")
def vae():
    return load_vae()


def _vectors(it) -> np.ndarray:
    return np.stack([p.to_vector() for p in it.params])


def test_geodesic_beats_the_straight_line_where_a_thumb_turns_130_degrees(vae):
    """Barrett's thumb points to the wrist, Shadow's across the palm: on the straight latent line a
    step moves the thumb tip 22 mm; the bent path lets the thumb shorten on the way and must do
    clearly better, from the same two mean latents, with no new jumps and every hand plausible."""
    a, b = ohra.get_hand("barrett_hand", "base"), ohra.get_hand("shadow_hand_right", "base")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geo_path = vae.interpolate(a, b, 16)  # the default
        arc_path = vae.interpolate(a, b, 16, spacing="arc")
        (mu_a, _), (mu_b, _) = vae.encode(a), vae.encode(b)
    assert np.array_equal(geo_path.z[0], mu_a) and np.array_equal(geo_path.z[-1], mu_b)  # endpoints fixed
    ends = vae.decode_vectors(np.stack([mu_a, mu_b]))  # float32 decoding: batch size may change the last bits
    assert np.allclose(_vectors(geo_path)[[0, -1]], ends, atol=1e-6)
    assert geo_path.alphas[0] == 0.0 and geo_path.alphas[-1] == 1.0 and np.all(np.diff(geo_path.alphas) > 0)
    V, V_arc = _vectors(geo_path), _vectors(arc_path)
    worst, worst_arc = tip_moves(V).max(), tip_moves(V_arc).max()
    assert worst <= worst_arc - 0.001, (1e3 * worst, 1e3 * worst_arc)  # at least 1 mm better
    # ... with every thumb base where the training data put thumbs (the sampler's box, +5 mm): the unconstrained
    # bend reached 18.4 mm by folding a thumb back from a base 93 mm behind the wrist (now 20.1 mm)
    lo, hi = thumb_box(V[[0, -1]])
    assert thumb_excursion(V, lo, hi) <= THUMB_BOX_MARGIN_M + 1e-9
    # the path is bent: its interior latents leave the straight line between the endpoints
    u = (mu_b - mu_a) / np.linalg.norm(mu_b - mu_a)
    off = geo_path.z - mu_a - np.outer((geo_path.z - mu_a) @ u, u)
    assert np.linalg.norm(off, axis=1).max() > 0.1
    assert structure_changes(V).sum() <= structure_changes(V_arc).sum()
    assert not geo.knuckles_inside_palm(V).any() and not geo.thumb_into_palm(V).any()
    assert not any(HandModel.from_params(BaseParams.from_vector(v)).self_collision(np.zeros(22)) for v in V)


@pytest.mark.e2e  # two full geodesics (~2-6 s): moved out of the default suite (stop 57) to keep it near 5 min
def test_geodesic_is_deterministic(vae):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one = vae.interpolate("dex3_right", "shadow_hand_right", 6)
        two = vae.interpolate("dex3_right", "shadow_hand_right", 6)
    assert np.array_equal(one.z, two.z) and np.array_equal(one.alphas, two.alphas)
    assert all(p.isclose(q) for p, q in zip(one.params, two.params))


def test_the_module_level_interpolate_takes_the_same_default_path_as_the_method():
    """``ohra.learn.interpolate(a, b, n, vae=vae)`` is ``vae.interpolate(a, b, n)``: the geodesic by
    default (it defaulted to the straight line at equal arc length); a given ``spacing`` passes through.
    (A stand-in model records the call: a real geodesic of more than 3 hands takes seconds.)"""
    import inspect

    from ohra.learn import morph

    default = inspect.signature(morph.VAEBundle.interpolate).parameters["spacing"].default
    assert default == "geodesic"

    class Recorder:
        def __init__(self):
            self.calls = []

        def interpolate(self, a, b, n=8, spacing=default):
            self.calls.append((a, b, n, spacing))
            return "interpolation"

    rec = Recorder()
    assert morph.interpolate("dex3_right", "shadow_hand_right", 5, vae=rec) == "interpolation"
    morph.interpolate("dex3_right", "shadow_hand_right", vae=rec, spacing="even")
    assert rec.calls == [("dex3_right", "shadow_hand_right", 5, "geodesic"), ("dex3_right", "shadow_hand_right", 8, "even")]


def test_the_energy_tips_equal_the_torch_fk_at_q0(vae):
    """The geodesic's closed-form q = 0 tips (base + reach along the finger) are the FK's tips."""
    geom = GeometryLoss(vae.model.config, vae.standardizer.mean, vae.standardizer.std)
    z = torch.randn(64, vae.latent_dim, generator=torch.Generator().manual_seed(3)) * 2.0
    with torch.no_grad():
        out = vae.model.decode(z)
        present = out["presence"][:, :22] > 0
        raw = out["cont"] * geom.std + geom.mean
        R = geom.thumb_rotation(raw)
        fk = tips(raw[:, 8:23].reshape(-1, 5, 3), raw[:, 2:8].reshape(-1, 2, 3), R, torch.zeros(64, 2, 3), raw[:, 23:29], present)
        closed = _tips_q0(raw, R[:, :, 2], present)
    assert torch.allclose(closed, fk, atol=1e-6)


def test_arc_length_resample_splits_a_polyline_evenly(vae):
    """Through three knots (a bend in latent space) the resampled hands move the fingertips by equal
    amounts, measured on a dense decoding of the same polyline; endpoints are the first and last knot."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mu, _ = vae.encode(["allegro_hand_right", "leap_hand_right", "inspire_hand_right"])
    z, s = arc_length_resample(vae, mu, 9)
    assert np.array_equal(z[0], mu[0]) and np.array_equal(z[-1], mu[-1]) and s[0] == 0 and s[-1] == 1
    steps = tip_moves(vae.decode_vectors(z))
    kept = steps[steps > 0]
    assert len(kept) >= 4 and kept.max() <= 1.3 * np.median(kept), 1e3 * steps


def test_a_user_hand_far_from_the_training_data_keeps_its_thumb_on_the_palm(vae):
    """PSYONIC Ability (parsed from dex-urdf; outside the sampler's support) -> Shadow, geodesic: one step flung
    the thumb base 127 mm out on a 55 mm palm (82 mm beyond any sampled or end thumb), its tip folded back
    onto the path, which measures tips only. A thumb base now stays in the box of the training data's and
    the two hands' thumb bases (+5 mm)."""
    from ohra.canonical.params import load_params

    ability = load_params(Path(__file__).parent / "data" / "ability_hand_right_base.json")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        path = vae.interpolate(ability, ohra.get_hand("shadow_hand_right", "base"), 8)
    V = _vectors(path)
    lo, hi = thumb_box(V[[0, -1]])
    assert thumb_excursion(V, lo, hi) <= THUMB_BOX_MARGIN_M + 1e-9, 1e3 * thumb_excursion(V, lo, hi)


def test_encoding_a_hand_outside_the_training_data_says_so_and_names_it(vae):
    """`ohra vae encode` of the Ability hand only warned about snapped thumb axes, for no hand in particular;
    its latent decodes with a 69 mm third thumb segment it does not have."""
    from ohra.learn import AxisSnapWarning, OutOfSupportWarning

    ability = str(Path(__file__).parent / "data" / "ability_hand_right_base.json")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vae.encode([ability, "shadow_hand_right"])
    out = [str(w.message) for w in caught if w.category is OutOfSupportWarning]
    assert len(out) == 1 and out[0].startswith(f"{ability}: outside the hands the VAE was trained on (joint pattern")
    snaps = [str(w.message) for w in caught if w.category is AxisSnapWarning]
    assert {m.split(":")[0] for m in snaps} == {ability, "shadow_hand_right"}


def test_a_thumb_alone_encodes_and_is_named_outside_the_training_data(vae):
    """support_violations() took np.ptp of an empty knuckle row: encoding a thumb-only hand raised a bare ValueError."""
    from ohra.learn import OutOfSupportWarning

    shadow = ohra.get_hand("shadow_hand_right", "base")
    lo, up = shadow.joint_lowers.copy(), shadow.joint_uppers.copy()
    lo[5:] = up[5:] = 0.0  # every finger but the thumb gone
    thumb = BaseParams.from_vector(shadow.to_vector())
    thumb = BaseParams(**{**{k: getattr(thumb, k) for k in ("palm_radius", "finger_radius", "finger_lengths", "finger_xyz",
                                                          "little_extra_origin", "thumb_rpy", "thumb_axes")},
                          "joint_lowers": lo, "joint_uppers": up})
    assert thumb.num_fingers == 1
    with pytest.warns(OutOfSupportWarning, match="no finger besides the thumb"):
        mu, _ = vae.encode(thumb)
    assert np.all(np.isfinite(mu))
