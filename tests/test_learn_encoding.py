"""The 66-D morphology encoding: layout, exact round trips, axis snapping, always-valid decoding."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

import ohra
from ohra.errors import ParamsError
from ohra.hands import registry
from ohra.learn.encoding import (
    AXIS1, AXIS2, CONT, FLAGS, AxisSnapWarning, LatentError, Standardizer, decode_params, decode_vectors,
    encode_params, encode_vectors, project_vectors, segment_presence,
)
from ohra.learn.sampler import BASIS_AXES, sample_vectors
from ohra.learn.sampler_reference import sample_reference_vectors
from ohra.canonical.params import BaseParams, ExtendedParams

# Reference §3.1, verbatim: the published Shadow right hand (basis thumb axes).
SHADOW_REF = {
    "palm_radius": 0.05, "finger_radius": 0.0087,
    "finger_lengths": [[0.038, 0.032, 0.035], [0.045, 0.025, 0.035]],
    "finger_xyz": [[0.0086, 0.034, 0.029], [0.0, 0.033, 0.095], [0.0, 0.011, 0.099], [0.0, -0.011, 0.095], [0.0, -0.033, 0.0866]],
    "little_extra_origin": [0.0, -0.033, 0.0207, 0.9599, 0.0, 0.0],
    "thumb_rpy": [0.0, -0.7854, -1.5708],
    "thumb_axes": [[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]],
    "joint_lowers": [[-1.0472, 0.0, -0.2094, -0.6981, -0.2618], [-0.3491, -0.2618, 0.0, 0.0], [-0.3491, -0.2618, 0.0, 0.0], [-0.3491, -0.2618, 0.0, 0.0], [0.0, -0.3491, -0.2618, 0.0, 0.0]],
    "joint_uppers": [[1.0472, 1.2217, 0.2094, 0.6981, 1.5708], [0.3491, 1.5708, 1.5708, 1.5708], [0.3491, 1.5708, 1.5708, 1.5708], [0.3491, 1.5708, 1.5708, 1.5708], [0.7854, 0.3491, 1.5708, 1.5708, 1.5708]],
}


# The registered hands with a base form, written out (not read from the registry at import, where a
# broken registry would silently parametrize nothing); test_registered_hands_exist keeps it in step.
BASE_HANDS = [
    "allegro_hand_left", "allegro_hand_right", "barrett_hand", "dex3_left", "dex3_right", "gaia_hand_left",
    "gaia_hand_right", "inspire_hand_left", "inspire_hand_right",
    "leap_hand_left", "leap_hand_right", "shadow_hand_left", "shadow_hand_right",
    "sharpa_wave_left", "sharpa_wave_right",
]


def test_layout_of_the_reference_shadow_hand():
    p = BaseParams.from_dict(SHADOW_REF)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # basis axes: no snapping warning
        x = encode_params(p)
    assert x.shape == (66,)
    assert np.array_equal(x[CONT], p.to_vector()[:32])
    assert x[0] == 0.05 and x[1] == 0.0087 and np.array_equal(x[29:32], [0.0, -0.7854, -1.5708])
    assert np.array_equal(x[AXIS1], [0, 0, 0, 0, 0, 1])  # -z  (order +x, -x, +y, -y, +z, -z)
    assert np.array_equal(x[AXIS2], [0, 1, 0, 0, 0, 0])  # -x
    assert np.array_equal(x[FLAGS], np.ones(22))


def test_flags_are_movable_joints_and_a_zero_axis_encodes_as_plus_x():
    d = dict(SHADOW_REF, thumb_axes=[[0, 0, 0], [0, 0, 0]])
    lo = np.array(sum(SHADOW_REF["joint_lowers"], []))
    up = np.array(sum(SHADOW_REF["joint_uppers"], []))
    lo[:2] = up[:2] = 0.0  # thumb joints 1, 2 absent
    lo[5] = up[5] = 0.088  # frozen but present (Allegro style): not a VAE flag
    d["joint_lowers"], d["joint_uppers"] = lo, up
    x = encode_params(BaseParams.from_dict(d))
    assert x[AXIS1][0] == 1 and x[AXIS2][0] == 1
    assert x[FLAGS][[0, 1, 5]].sum() == 0 and x[FLAGS].sum() == 19


def test_round_trip_is_exact_for_sampled_hands():
    v = sample_vectors(3000, 5)
    x = encode_vectors(v)
    assert np.array_equal(decode_vectors(x), v)  # sampled limits are the default [0, pi/2]
    assert np.array_equal(decode_vectors(x, limits=np.concatenate([v[:, 38:60], v[:, 60:82]], axis=1)), v)
    assert np.array_equal(project_vectors(v), v)


def _snapped(p: BaseParams) -> np.ndarray:
    v = p.to_vector().copy()
    axes = v[32:38].reshape(2, 3)
    for k in range(2):
        if np.any(axes[k]):
            axes[k] = BASIS_AXES[np.argmax(BASIS_AXES @ axes[k])]
    v[32:38] = axes.reshape(6)
    return v


@pytest.mark.parametrize("name", BASE_HANDS)
def test_round_trip_is_exact_for_registered_hands_with_axes_snapped(name):
    p = ohra.get_hand(name, "base")
    is_basis = all(not np.any(a) or np.isin(a, (-1.0, 0.0, 1.0)).all() for a in p.thumb_axes)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        x = encode_params(p)
    snaps = [w for w in caught if issubclass(w.category, AxisSnapWarning)]
    assert bool(snaps) == (not is_basis)
    if snaps:
        assert "thumb_axes[" in str(snaps[0].message)
    q = decode_params(x, limits=p)
    assert np.array_equal(q.to_vector(), _snapped(p))


def test_registered_hands_exist():
    """The registry's base-form hands are exactly BASE_HANDS (add a new hand there to test it)."""
    registered = [n for n in ohra.list_hands() if "base" in registry.registered_forms(n)]
    assert registered == BASE_HANDS


def test_non_basis_axes_snap_to_the_nearest_signed_basis_axis():
    d = dict(SHADOW_REF, thumb_axes=[[-0.6428, 0.419, -0.6413], [0.1, -0.99, 0.05]])
    d["thumb_axes"] = (np.array(d["thumb_axes"]) / np.linalg.norm(d["thumb_axes"], axis=1, keepdims=True)).tolist()
    with pytest.warns(AxisSnapWarning, match=r"-> -x .*-> -y"):
        x = encode_params(BaseParams.from_dict(d))
    assert x[AXIS1].argmax() == 1 and x[AXIS2].argmax() == 3


def test_extended_params_encode_through_their_base_form_or_fail_clearly():
    shadow = BaseParams.from_dict(SHADOW_REF)
    assert np.array_equal(encode_params(shadow.to_extended()), encode_params(shadow))
    ext = shadow.to_extended()
    radii = ext.finger_radii.copy()
    radii[2] *= 1.2
    other = ExtendedParams.from_dict(dict(ext.to_dict(), finger_radii=radii.tolist()))
    with pytest.raises(ParamsError, match="base"):
        encode_params(other)


@pytest.mark.parametrize("scale", [1.0, 10.0, 1e3, 1e8])
def test_decoding_any_encoding_gives_valid_params(scale):
    rng = np.random.default_rng(int(scale))
    x = rng.normal(0.0, scale, (300, 66))
    v = decode_vectors(x)
    for row in v:
        BaseParams.from_vector(row)
    # the projection enforces physical sense, not just validity
    present = (v[:, 38:60] != 0) | (v[:, 60:82] != 0)
    seg_t, seg_f, fingers = segment_presence(present)
    r = v[:, 1]
    lengths = v[:, 2:8].reshape(-1, 2, 3)
    seg = np.stack([seg_t, seg_f.any(axis=1)], axis=1)
    assert (lengths[seg] >= 2 * np.repeat(r, 6).reshape(-1, 2, 3)[seg] - 1e-12).all()
    y = v[:, 8:23].reshape(-1, 5, 3)[:, 1:, 1]
    for i in range(len(v)):
        yi = np.sort(y[i, fingers[i, 1:]])
        assert (np.diff(yi) >= 2 * r[i] - 1e-9).all()
    assert np.array_equal(project_vectors(v), v), "projection is idempotent"
    assert (v[:, 60:82][present] == pytest.approx(math.pi / 2)) and not v[:, 38:60].any()


def test_limits_sources_and_errors():
    v = sample_vectors(4, 1)
    x = encode_vectors(v)
    shadow = BaseParams.from_dict(SHADOW_REF)
    a = decode_vectors(x, limits=shadow)
    b = decode_vectors(x, limits=(shadow.joint_lowers, shadow.joint_uppers))
    c = decode_vectors(x, limits=np.concatenate([shadow.joint_lowers, shadow.joint_uppers]))
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert np.array_equal(a[:, 38:60], np.tile(shadow.joint_lowers, (4, 1)))
    with pytest.raises(ParamsError, match="limits"):
        decode_vectors(x, limits=np.zeros(7))
    with pytest.raises(ParamsError, match="lowers <= uppers"):
        decode_vectors(x, limits=(np.ones(22), np.zeros(22)))
    with pytest.raises(LatentError, match=r"\(66,\)"):
        decode_vectors(np.zeros(65))
    with pytest.raises(LatentError, match="non-finite"):
        decode_vectors(np.full(66, np.nan))
    with pytest.raises(LatentError, match=r"\(82,\)"):
        encode_vectors(np.zeros((3, 81)))


def test_standardizer_round_trip_and_constant_dimensions():
    v = sample_reference_vectors(2000, 2)  # its little metacarpal frame has no pitch and yaw
    cont = encode_vectors(v)[:, CONT]
    s = Standardizer.fit(cont)
    z = s.transform(cont)
    assert np.allclose(s.inverse(z), cont, atol=1e-15)
    const = np.ptp(cont, axis=0) == 0  # little extra pitch and yaw are always 0
    assert const.sum() >= 2 and np.all(s.std[const] == 1.0)
    assert np.allclose(z[:, ~const].mean(axis=0), 0, atol=1e-9) and np.allclose(z[:, ~const].std(axis=0), 1)
    assert Standardizer.from_dict(s.to_dict()).std.tolist() == s.std.tolist()
    with pytest.raises(ParamsError, match="positive stds"):
        Standardizer.from_dict({"mean": [0.0, 1.0], "std": [1.0, 0.0]})


def test_sampler_and_encoding_import_without_torch_and_torch_parts_say_how_to_install():
    code = (
        # a finder that refuses torch (sys.modules['torch'] = None would also break scipy's array-API probing)
        "import sys\n"
        "class NoTorch:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'torch' or name.startswith('torch.'):\n"
        "            raise ImportError('No module named torch')\n"
        "sys.meta_path.insert(0, NoTorch())\n"
        "import ohra.learn as L\n"
        "v = L.sample_vectors(8, 0); x = L.encode_vectors(v); L.decode_params(x)\n"
        "from ohra.learn import encoding_rot6d as E; E.decode_vectors(E.encode_vectors(v))\n"
        "assert 'torch' not in sys.modules\n"
        "try:\n    L.load_vae\nexcept L.MissingDependencyError as e:\n    print('ERR', e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "ERR" in out.stdout and "pip install ohra[learn]" in out.stdout
