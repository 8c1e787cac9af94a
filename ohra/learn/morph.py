"""Using a trained morphology VAE: load it, encode hands, decode latents, interpolate between hands.

``load_vae()`` reads the model shipped with the package (``ohra/learn/models/vae_default``,
through ``importlib.resources``, no network); ``load_vae(DIR)`` reads a run directory written by
``ohra train vae -o DIR`` (its ``model.pt``, or ``checkpoints/last.pt`` if training is unfinished).

Encoding is deterministic: the encoder runs in eval mode (BatchNorm running statistics) and
``encode`` returns the mean and log-variance; interpolation uses the means (the reference sampled
``z``, which makes the endpoints noisy) and places its hands at equal fingertip arc length along a
latent path bent to shorten the fingertips' way, or along the straight line
(:mod:`ohra.learn.latent_path`). Decoding always yields valid :class:`BaseParams`
(see :func:`ohra.learn.encoding.project_vectors`), for any finite or infinite latent.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from collections.abc import Iterable
from typing import Any, Sequence, Union

import numpy as np
import torch

from ohra.errors import CheckpointError, ParamsError, user_stacklevel
from ohra.canonical.params import BaseParams, ExtendedParams
from ohra.canonical.urdfgen import render
from ohra.learn.encoding import LatentError, OutOfSupportWarning, Standardizer, as_base
from ohra.learn.encodings import Encoding, get_encoding
from ohra.learn.latent_path import ARC_DENSITY, arc_length_alphas, geodesic_latents, tip_moves  # noqa: F401 (re-exported)
from ohra.learn.train_vae import CHECKPOINT_FORMAT, MODEL_FORMAT, load_torch_file
from ohra.learn.vae import MorphologyVAE, VAEConfig

FAR_LATENT = 8.0  # |z| beyond this many prior standard deviations: decode warns that the hand is extrapolated

HandLike = Union[str, Path, BaseParams, ExtendedParams]
DEFAULT_MODEL = "vae_default"
REFERENCE_MODEL = "vae_reference66"  # the paper-setting model shipped before, kept for comparison
_BIG = 1e6  # replaces infinities in decoder outputs before projection (then clipped to the bounds)


def default_model_dir() -> Path:
    """Folder of the model shipped with the package."""
    return Path(str(resources.files("ohra.learn").joinpath("models", DEFAULT_MODEL)))


def reference_model_dir() -> Path:
    """Folder of the kept reference model (66-D encoding, paper settings)."""
    return Path(str(resources.files("ohra.learn").joinpath("models", REFERENCE_MODEL)))


def resolve_hand(hand: HandLike) -> BaseParams:
    """Base params of a registered hand name, a params JSON path, or params."""
    if isinstance(hand, (BaseParams, ExtendedParams)):
        return as_base(hand)
    from ohra.hands import get_hand

    if Path(str(hand)).suffix == ".json":  # a file's own form: as_base names the VAE's need if it has no base form
        try:
            return as_base(get_hand(str(hand)))
        except ParamsError as exc:
            raise ParamsError(f"hand {str(hand)!r}: {exc}") from None  # two hands to encode: which one
    return as_base(get_hand(str(hand), "base"))


def _label(hand: str) -> str:
    """How a strip or scene names an endpoint: a spec YAML by its hand's name, a file by its stem, a name as given."""
    if Path(hand).suffix in (".yaml", ".yml") and Path(hand).is_file():
        from ohra.original.spec import load_spec

        return load_spec(hand).name
    return Path(hand).stem


@dataclass
class VAEBundle:
    """A trained VAE in eval mode with its standardiser, training configuration and metrics."""

    model: MorphologyVAE
    standardizer: Standardizer
    config: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] | None = None
    path: Path | None = None

    @property
    def latent_dim(self) -> int:
        return self.model.config.latent_dim

    def __repr__(self) -> str:  # the dataclass default prints every layer and the standardiser's arrays
        return (f"VAEBundle(encoding={self.model.config.encoding!r}, latent_dim={self.latent_dim}, "
                f"path={str(self.path) if self.path else None!r})")

    @property
    def encoding(self) -> Encoding:
        """The encoding this model was trained on (``reference66`` or ``rot6d70``)."""
        return get_encoding(self.model.config.encoding)

    # -- encoding -----------------------------------------------------------------------------
    def encode_vectors(self, v82: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Base vectors (N, 82) -> (mu, logvar), each (N, latent_dim) (axes snapped silently)."""
        return self.encode_encodings(self.encoding.encode_vectors(np.atleast_2d(v82), warn=False))

    def encode_encodings(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw encodings (N, D) -> (mu, logvar), each (N, latent_dim)."""
        enc = self.encoding
        x = np.array(x, dtype=float, copy=True)
        x[:, enc.cont] = self.standardizer.transform(x[:, enc.cont])
        with torch.no_grad():
            mu, logvar = self.model.encode(torch.from_numpy(x.astype(np.float32)))
        return mu.double().numpy(), logvar.double().numpy()

    def encode(self, hands: HandLike | Sequence[HandLike]) -> tuple[np.ndarray, np.ndarray]:
        """Mean and log-variance of the encoder's posterior (eval mode: deterministic).

        Args:
            hands: one hand or a sequence of N hands, each a registered hand name, a spec YAML or params
                JSON path (base form), or :class:`BaseParams` / :class:`ExtendedParams` with a base form.
                Thumb axes off the basis axes are snapped to the nearest one (with a warning).

        Returns:
            (mu, logvar): float64, each (latent_dim,) for one hand or (N, latent_dim) for a sequence.

        Raises:
            HandNotFoundError: an unknown name or a missing file; a name with no base form (a LEAP
                variant, an extended-only hand).
            ParamsError: extended params with no base form; an empty sequence.
        """
        single = isinstance(hands, (str, Path, BaseParams, ExtendedParams))
        if not single and not isinstance(hands, Iterable):
            raise ParamsError(f"encode: expected a hand (name, file or params) or a sequence of them, got "
                              f"{type(hands).__name__}")
        items = [hands] if single else list(hands)
        if not items:
            raise ParamsError("encode: no hands given (expected a hand or a non-empty sequence of hands)")
        x = np.stack([self._encode_one(h) for h in items])
        mu, logvar = self.encode_encodings(x)
        return (mu[0], logvar[0]) if single else (mu, logvar)

    def _encode_one(self, hand: HandLike) -> np.ndarray:
        """The encoding of one hand; its warnings (snapped thumb axes, a hand outside the training data) name it."""
        from ohra.learn.sampler import support_violations, violations_text

        label = hand if isinstance(hand, (str, Path)) else f"{type(hand).__name__}({hand.num_fingers} fingers)"
        params = resolve_hand(hand)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            x = self.encoding.encode_vectors(params.to_vector())
        for w in caught:
            warnings.warn(f"{label}: {w.message}", w.category, stacklevel=user_stacklevel())
        why = support_violations(params)
        if why:
            # the decoder was trained on the sampler's hands: a latent of a hand outside them may decode to another
            # hand (Ability's decodes with a 69 mm third thumb segment)
            warnings.warn(f"{label}: outside the hands the VAE was trained on ({violations_text(why)}); its latent may not "
                          "decode back to it",
                          OutOfSupportWarning, stacklevel=user_stacklevel())
        return x

    # -- decoding -----------------------------------------------------------------------------
    def check_latent(self, z: Any) -> tuple[np.ndarray, bool]:
        try:
            arr = np.asarray(z, dtype=float)
        except (TypeError, ValueError):
            raise LatentError(f"latent: expected numbers, got {type(z).__name__}") from None
        d = self.latent_dim
        if arr.ndim not in (1, 2) or arr.shape[-1] != d:
            raise LatentError(f"latent: expected shape ({d},) or (N, {d}), got {arr.shape}")
        if np.isnan(arr).any():
            raise LatentError("latent contains NaN")
        return np.atleast_2d(arr), arr.ndim == 1

    def decode_encodings(self, z: Any) -> np.ndarray:
        """Latents (N, latent_dim) -> raw decoder outputs (N, D): continuous in raw units, axis
        logits, presence probabilities."""
        zz, _ = self.check_latent(z)
        zz = np.clip(zz, -1e30, 1e30)  # keep float32 finite; the projection clips the result anyway
        enc = self.encoding
        with torch.no_grad():
            out = self.model.decode(torch.from_numpy(zz.astype(np.float32)))
        clean = lambda t: np.nan_to_num(t.double().numpy(), nan=0.0, posinf=_BIG, neginf=-_BIG)  # noqa: E731
        y = np.zeros((len(zz), enc.dim))
        y[:, enc.cont] = np.nan_to_num(self.standardizer.inverse(clean(out["cont"])), nan=0.0, posinf=_BIG, neginf=-_BIG)
        y[:, enc.axis1] = clean(out["axis1"])
        y[:, enc.axis2] = clean(out["axis2"])
        y[:, enc.binary] = np.nan_to_num(torch.sigmoid(out["presence"]).double().numpy(), nan=0.0)
        return y

    def decode_vectors(self, z: Any, limits: Any = None) -> np.ndarray:
        """Latents -> valid base vectors (N, 82) (or (82,) for one latent); see the encoding's
        ``decode_vectors`` (the rot6d encoding also makes them plausible)."""
        _, single = self.check_latent(z)
        v = self.encoding.decode_vectors(self.decode_encodings(z), limits)
        return v[0] if single else v

    def decode(self, z: Any, limits: Any = None) -> BaseParams | list[BaseParams]:
        """Valid base-form hands for latents (any finite or infinite values; see the module docstring).

        Args:
            z: one latent (latent_dim,) or N latents (N, latent_dim).
            limits: joint limits [rad] of the decoded hands, as in
                :func:`ohra.learn.encoding.decode_vectors`: None gives ``[0, pi/2]`` to the joints the
                decoder marks present (0 to absent ones); else params (or a list of N), a
                ``(lowers, uppers)`` pair of (22,) or (N, 22), or a (44,) / (N, 44) array.

        Returns:
            One :class:`BaseParams` for a (latent_dim,) latent, a list of N for (N, latent_dim).

        Raises:
            LatentError: ``z`` is not numeric, not of shape (latent_dim,) or (N, latent_dim), or holds NaN.
            ParamsError: malformed ``limits`` (shape, non-finite, a lower above its upper).
        """
        zz, _ = self.check_latent(z)
        far = float(np.abs(zz).max()) if zz.size else 0.0
        if far > FAR_LATENT:
            warnings.warn(f"latent component {far:.3g} lies far outside the VAE's prior (a unit Gaussian; beyond "
                          f"{FAR_LATENT:g}): the decoded hand is valid but need not resemble any hand it learned",
                          UserWarning, stacklevel=user_stacklevel())
        v = self.decode_vectors(z, limits)
        if v.ndim == 1:
            return BaseParams.from_vector(v)
        return [BaseParams.from_vector(row) for row in v]

    def reconstruct(self, hand: HandLike, keep_limits: bool = True) -> BaseParams:
        """Encode (mean) and decode one hand; with ``keep_limits`` the hand's own joint limits are kept."""
        p = resolve_hand(hand)
        mu, _ = self.encode(p)
        return self.decode(mu, limits=p if keep_limits else None)  # type: ignore[return-value]

    # -- interpolation ------------------------------------------------------------------------
    def interpolate(self, a: HandLike, b: HandLike, n: int = 8, spacing: str = "geodesic") -> "Interpolation":
        """``n`` hands from the mean latent of ``a`` to that of ``b`` (endpoints included), decoded with
        default limits [0, pi/2] for present joints (see :mod:`ohra.learn.latent_path`).

        Args:
            a, b: the end hands, as :meth:`encode` takes them.
            n: number of hands, >= 2.
            spacing: ``"geodesic"``: a bent latent path of short fingertip travel, at equal fingertip
                arc length (:func:`geodesic_latents`; never a larger step than ``"arc"``, ~0.5-2 s);
                ``"arc"``: the straight latent line at equal fingertip arc length
                (:func:`arc_length_alphas`); ``"even"``: the straight line at ``alphas = linspace(0, 1, n)``.

        Returns:
            :class:`Interpolation` with ``alphas`` (n,) (the hands' places along the path, 0 to 1; for
            the geodesic the fraction of the bent path), latents ``z`` (n, latent_dim), the decoded
            ``params`` and their URDF texts, and the two end hands in base form.

        Raises:
            LatentError: ``n < 2`` or an unknown ``spacing``.
            HandNotFoundError, ParamsError: an end hand cannot be encoded (see :meth:`encode`).
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise LatentError(f"interpolation needs a whole number of at least 2 steps, got {n!r}")
        if spacing not in SPACINGS:
            raise LatentError(f"interpolation spacing must be one of {SPACINGS}, got {spacing!r}")
        n = int(n)
        (mu_a, _), (mu_b, _) = self.encode(a), self.encode(b)
        if spacing == "geodesic":
            z, alphas = geodesic_latents(self, mu_a, mu_b, n)
        else:
            alphas = arc_length_alphas(self, mu_a, mu_b, n) if spacing == "arc" else np.linspace(0.0, 1.0, n)
            z = (1.0 - alphas)[:, None] * mu_a + alphas[:, None] * mu_b
        params = self.decode(z)
        assert isinstance(params, list)
        names = [str(a) if isinstance(a, (str, Path)) else "hand_a", str(b) if isinstance(b, (str, Path)) else "hand_b"]
        return Interpolation(alphas, z, params, [render(p, robot_name=f"vae_interp_{i}") for i, p in enumerate(params)],
                             tuple(_label(x) for x in names), (resolve_hand(a), resolve_hand(b)))


SPACINGS = ("geodesic", "arc", "even")


@dataclass
class Interpolation:
    """A latent interpolation: ``alphas`` (n,) (where each hand sits on the path, 0 to 1), latents
    ``z`` (n, d), decoded ``params`` and their ``urdfs``; ``originals`` are the two hands it was made
    from (base form), for pictures."""

    alphas: np.ndarray
    z: np.ndarray
    params: list[BaseParams]
    urdfs: list[str]
    endpoints: tuple[str, str] = ("hand_a", "hand_b")
    originals: tuple[BaseParams, BaseParams] | None = None

    def __len__(self) -> int:
        return len(self.params)

    def labels(self) -> list[str]:
        return [f"{i}: a={a:.2f}" for i, a in enumerate(self.alphas)]

    def labelled_originals(self) -> list[tuple[str, BaseParams]] | None:
        """``[("original <a>", params_a), ("original <b>", params_b)]`` for :func:`ohra.learn.strip.strip_png`."""
        if self.originals is None:
            return None
        return [(f"original {name}", p) for name, p in zip(self.endpoints, self.originals)]

    def write(self, out_dir: str | Path, stem: str = "interp") -> list[Path]:
        """Write ``<stem>_<i>.urdf`` and ``<stem>_<i>.json`` (params) for every step; returns the URDF paths."""
        from ohra.io import check_output, write_text

        out = check_output(out_dir, folder=True)
        paths = []
        for i, (p, text) in enumerate(zip(self.params, self.urdfs)):
            path = out / f"{stem}_{i:02d}.urdf"
            write_text(path, text)
            write_text(out / f"{stem}_{i:02d}.json", p.to_json())
            paths.append(path)
        summary = {"endpoints": list(self.endpoints), "alphas": self.alphas.tolist(), "z": self.z.tolist(),
                   "dof": [p.dof for p in self.params], "fingers": [p.num_fingers for p in self.params]}
        write_text(out / f"{stem}.json", json.dumps(summary, indent=1) + "\n")
        return paths


# -- loading ----------------------------------------------------------------------------------------
def _read_json(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise CheckpointError(f"{path}: malformed JSON ({exc})") from None


def bundle_from_payload(obj: dict[str, Any], where: str) -> tuple[MorphologyVAE, Standardizer]:
    """Model and standardiser from a ``model.pt`` or checkpoint dict (:class:`CheckpointError` if broken)."""
    try:
        cfg = VAEConfig.from_dict(obj["vae_config"])
        std = Standardizer.from_dict({k: np.asarray(v, dtype=float) for k, v in obj["standardizer"].items()})
        model = MorphologyVAE(cfg)
        model.load_state_dict(obj["model"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{where}: incompatible VAE weights ({type(exc).__name__}: {str(exc).splitlines()[0][:160]})") from None
    model.eval()
    return model, std


def load_vae(path: str | Path | None = None) -> VAEBundle:
    """Load a VAE in eval mode.

    Args:
        path: None for the shipped model (loaded once, then the same bundle is returned); a run or
            model directory (its ``model.pt``, else ``checkpoints/last.pt``); or a ``.pt`` file
            (``model.pt`` or a training checkpoint).

    Returns:
        :class:`VAEBundle`: the model, its standardiser, the training config (``config.json`` beside
        the file, else the checkpoint's) and ``metrics.json`` if present.

    Raises:
        CheckpointError: no model file there; a corrupt, foreign or other-version file; weights that
            do not fit the stored config; malformed ``config.json`` / ``metrics.json``.
    """
    if path is None:
        return _load_default()
    return _load(Path(path))


@lru_cache(maxsize=1)
def _load_default() -> VAEBundle:
    d = default_model_dir()
    if not (d / "model.pt").is_file():
        raise CheckpointError(f"the shipped VAE model is missing ({d / 'model.pt'}); reinstall ohra or train one with `ohra train vae`")
    return _load(d)


def _load(p: Path) -> VAEBundle:
    if p.is_dir():
        folder = p
        f = p / "model.pt"
        if not f.is_file() and (p / "checkpoints" / "last.pt").is_file():
            f = p / "checkpoints" / "last.pt"
    else:
        folder, f = p.parent, p
    if not f.exists():
        raise CheckpointError(f"no VAE model at {p} (expected model.pt or checkpoints/last.pt)")
    try:
        obj = load_torch_file(f, MODEL_FORMAT)
    except CheckpointError:
        obj = load_torch_file(f, CHECKPOINT_FORMAT)  # a training checkpoint works too
    model, std = bundle_from_payload(obj, str(f))
    config = _read_json(folder / "config.json") or dict(obj.get("config", {}))
    return VAEBundle(model, std, config, _read_json(folder / "metrics.json"), f)


# -- module-level shortcuts (shipped model unless ``vae`` is given) ----------------------------------
def encode(hand: HandLike | Sequence[HandLike], vae: VAEBundle | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(mu, logvar) of a hand (name, params JSON path or params) as numpy arrays."""
    return (vae or load_vae()).encode(hand)


def decode(z: Any, vae: VAEBundle | None = None, limits: Any = None) -> BaseParams | list[BaseParams]:
    """Valid :class:`BaseParams` for a latent (or a list for (N, d) latents)."""
    return (vae or load_vae()).decode(z, limits)


def interpolate(hand_a: HandLike, hand_b: HandLike, n: int = 8, vae: VAEBundle | None = None,
                spacing: str = "geodesic") -> Interpolation:
    """Decoded hands (params + URDF texts) from ``hand_a`` to ``hand_b``: :meth:`VAEBundle.interpolate`
    of ``vae`` (default the shipped model), with the same default ``spacing``, ``"geodesic"`` (a bent
    latent path of short fingertip travel); ``"arc"`` or ``"even"`` for the straight latent line."""
    return (vae or load_vae()).interpolate(hand_a, hand_b, n, spacing)
