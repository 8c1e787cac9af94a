"""Settings of the grasp model and of its training (plain dataclasses: no torch needed to read them).

Both round-trip through JSON (``to_dict`` / ``from_dict``) and are stored next to every checkpoint,
so a run directory says exactly what made it.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field, fields
from typing import Any, TypeVar

from ohra.errors import OhraError, reject_unknown, require_finite, require_seed, require_whole

ENCODERS = ("pointnet", "dgcnn")
CONDITIONS = ("vae", "params")
_DEVICE = re.compile(r"cpu|cuda(:(0|[1-9]\d{0,3}))?|mps")


class GraspConfigError(OhraError, ValueError):
    """A grasp-model or training setting is out of range or unknown."""


MAX_WIDTH = 65536
"""Largest layer width (and object feature size, point count) a model setting takes: wider is a typo that would end in
an allocation failure (a 2**40-wide layer), not a model."""


def _whole(name: str, value: Any, least: int, most: int | None = None) -> None:
    require_whole(value, GraspConfigError, name, least, most)


def _real(name: str, value: Any, positive: bool = False) -> None:
    require_finite(value, GraspConfigError, name, positive)


def _names(name: str, value: Any) -> None:
    """``value`` is a tuple of strings (a bare string would be read letter by letter)."""
    if isinstance(value, str) or not isinstance(value, tuple) or not all(isinstance(v, str) for v in value):
        raise GraspConfigError(f"{name}: expected a tuple of names, got {value!r}")


_S = TypeVar("_S", bound="_JSONSettings")


class _JSONSettings:
    """``to_dict``/``from_dict`` of a settings dataclass whose tuples are JSON lists (in a run's
    ``config.json``)."""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}

    @classmethod
    def from_dict(cls: type[_S], d: dict[str, Any]) -> _S:
        """From a plain dict (lists become tuples); anything but a dict, or an unknown key, raises
        :class:`GraspConfigError`."""
        if not isinstance(d, dict):
            raise GraspConfigError(f"{cls.__name__}: expected a mapping, got {type(d).__name__}")
        reject_unknown(d, (f.name for f in fields(cls)), GraspConfigError, cls.__name__, "setting(s)")
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()}
        return cls(**kw)


@dataclass(frozen=True)
class GraspModelConfig(_JSONSettings):
    """Architecture of :class:`ohra.learn.grasp.model.GraspNet`.

    ``encoder``: ``"pointnet"`` (shared MLP + max-pool; ~200 clouds/s forward+backward with 512 points
    on one CPU core) or ``"dgcnn"`` (the paper's edge convolutions, k neighbours; ~3 clouds/s, i.e.
    days per run on a CPU). ``condition``: ``"vae"`` (frozen VAE mean latent, the unified model) or
    ``"params"`` (normalised raw canonical parameters, for hands the VAE cannot encode, e.g. LEAP
    variants). Diffusion: x0 prediction over the wrist translation (and, with ``diffuse_joints``, the
    22 joints too, in place of the joint network), ``train_steps`` noise levels, DDIM with
    ``inference_steps`` at sampling time.
    """

    encoder: str = "pointnet"
    n_points: int = 512  # object surface points fed to the encoder
    encoder_channels: tuple[int, ...] = (64, 128, 256)  # per-point MLP widths (pointnet) / edge-conv widths (dgcnn)
    object_dim: int = 256  # object feature size
    dgcnn_k: int = 20
    condition: str = "vae"
    denoiser_hidden: tuple[int, ...] = (512, 256)
    time_embed_dim: int = 64
    joint_hidden: int = 256
    joint_blocks: int = 2
    train_steps: int = 1000
    inference_steps: int = 10
    # |x0| bound in normalised translation units (RMS of the training translations); diffused joints are held within
    # the sampled hand's limits instead
    clip_sample: float = 4.0
    # the 22 joints as part of the diffusion (x = [translation, joints], each joint standardised by the training
    # data's mean and spread; no joint network) instead of the paper's joint network given the sampled translation
    diffuse_joints: bool = False

    def __post_init__(self) -> None:
        if self.encoder not in ENCODERS:
            raise GraspConfigError(f"encoder: expected one of {list(ENCODERS)}, got {self.encoder!r}")
        if self.condition not in CONDITIONS:
            raise GraspConfigError(f"condition: expected one of {list(CONDITIONS)}, got {self.condition!r}")
        for name in ("n_points", "object_dim", "time_embed_dim", "joint_hidden", "train_steps", "inference_steps", "dgcnn_k"):
            _whole(name, getattr(self, name), 1, MAX_WIDTH if name in ("n_points", "object_dim", "time_embed_dim", "joint_hidden") else None)
        _whole("joint_blocks", self.joint_blocks, 0)
        for name in ("encoder_channels", "denoiser_hidden"):
            if not isinstance(getattr(self, name), tuple):
                raise GraspConfigError(f"{name}: expected a tuple of widths, got {getattr(self, name)!r}")
            for k, w in enumerate(getattr(self, name)):
                _whole(f"{name}[{k}]", w, 1, MAX_WIDTH)
        if self.inference_steps > self.train_steps:
            raise GraspConfigError(f"inference_steps ({self.inference_steps}) exceeds train_steps ({self.train_steps})")
        if self.time_embed_dim % 2:
            raise GraspConfigError(f"time_embed_dim must be even, got {self.time_embed_dim}")
        if not self.encoder_channels or not self.denoiser_hidden:
            raise GraspConfigError("encoder_channels and denoiser_hidden need at least one width")
        if self.encoder == "dgcnn" and self.dgcnn_k > self.n_points:
            raise GraspConfigError(f"dgcnn_k ({self.dgcnn_k}) exceeds n_points ({self.n_points})")
        _real("clip_sample", self.clip_sample, positive=True)
        if not isinstance(self.diffuse_joints, bool):
            raise GraspConfigError(f"diffuse_joints: expected True or False, got {self.diffuse_joints!r}")



@dataclass(frozen=True)
class GraspTrainConfig(_JSONSettings):
    """Training settings. One step = one robot-balanced batch of ``batch_size`` grasps.

    Every distinct object of a batch is encoded ``rotated_copies`` times (each copy under its own
    uniformly random rotation, applied to the cloud and to the grasps assigned to it; 0: no
    rotation augmentation, one unrotated copy) and the feature is shared by its grasps, so the
    encoder cost scales with objects, not grasps. ``objects_per_step`` caps the distinct objects of
    a batch (0: no cap). Randomness of step ``s`` comes from ``(seed, s)`` alone, so training is
    reproducible and a resumed run equals an uninterrupted one.
    """

    steps: int = 3000
    batch_size: int = 128
    lr: float = 1e-3
    lr_min: float = 1e-6  # cosine annealing floor
    weight_decay: float = 0.0
    seed: int = 0
    threads: int = 1
    checkpoint_every: int = 250  # steps
    log_every: int = 25  # steps between history entries
    rotated_copies: int = 1
    objects_per_step: int = 0
    point_noise: float = 0.002  # m, i.i.d. Gaussian noise on training clouds (reference value)
    surface_pool: int = 4096  # surface points pre-sampled per object; each step draws n_points of them
    joint_loss_weight: float = 1.0
    hands: tuple[str, ...] = ()  # empty: every hand of the dataset
    test_objects: tuple[str, ...] = ()  # held out of training
    # held out of training by name and by canonical parameters (a renamed copy of a test hand is
    # held out too): the zero-shot models of the LEAP study never see a grasp of their test variant
    test_hands: tuple[str, ...] = ()
    max_per_pair: int = 0  # cap on grasps per (hand, object) (0: all)
    # std of i.i.d. Gaussian noise added to each training row's hand condition, in the condition's
    # units (params: standardised units; vae: latent units); 0: none. A regulariser for hands never
    # trained on: the model may not key on the exact condition of one training hand.
    condition_noise: float = 0.0
    # weight of the finger-object penetration term on the joint network (ohra.learn.grasp.contact; base-form
    # hands; 0: off) and the std [m] of the palm shift it is evaluated at (0: the data's palm; the contact
    # term below is evaluated at the same shifted palm)
    penetration_weight: float = 0.0
    penetration_shift: float = 0.0
    # weight of the two-sided finger-contact term (ohra.learn.grasp.contact.contact_gap: each finger link's
    # distance to the object pulled to the data's, both capped at 1 cm; base-form hands; 0: off)
    contact_weight: float = 0.0
    # its form: "capped" (both distances capped at 1 cm; stop 46's first arms) or "target" (only the data's
    # clear links capped: a link the data has on the surface is pulled there from any distance)
    contact_form: str = "capped"
    # torch device of the network and the batches ("cpu", "cuda", "cuda:1", "mps"); batches are drawn on the
    # CPU from (seed, step) whatever the device, so runs differ between devices only by float rounding. A run
    # may resume on another device; the saved model and checkpoints load on any machine.
    device: str = "cpu"

    RESUMABLE_CHANGES = ("steps", "checkpoint_every", "log_every", "device")

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "threads", "checkpoint_every", "log_every", "surface_pool"):
            _whole(name, getattr(self, name), 1)
        for name in ("rotated_copies", "objects_per_step", "max_per_pair"):
            _whole(name, getattr(self, name), 0)
        _real("lr", self.lr, positive=True)
        for name in ("lr_min", "point_noise", "joint_loss_weight", "condition_noise", "penetration_weight", "penetration_shift",
                     "contact_weight"):
            _real(name, getattr(self, name))
        if self.lr_min > self.lr:  # the cosine schedule would rise instead of anneal
            raise GraspConfigError(f"lr_min ({self.lr_min}) exceeds lr ({self.lr})")
        for name in ("hands", "test_objects", "test_hands"):
            _names(name, getattr(self, name))
        if not isinstance(self.device, str) or not _DEVICE.fullmatch(self.device):
            raise GraspConfigError(f"device: expected 'cpu', 'cuda', 'cuda:N' or 'mps' (a string), got {self.device!r}")
        if self.device != "cpu" and (self.penetration_weight > 0 or self.contact_weight > 0):
            raise GraspConfigError(f"device {self.device!r}: the penetration and contact terms run on the CPU only "
                                   "(train with device='cpu' or set their weights to 0)")
        if self.contact_form not in ("capped", "target"):
            raise GraspConfigError(f"contact_form must be 'capped' or 'target', got {self.contact_form!r}")
        require_seed(self.seed, GraspConfigError)



@dataclass
class RunSpec:
    """What a run directory's ``config.json`` holds: data location, model and training settings."""

    data: list[str] = field(default_factory=list)
    model: GraspModelConfig = field(default_factory=GraspModelConfig)
    train: GraspTrainConfig = field(default_factory=GraspTrainConfig)

    def to_dict(self) -> dict[str, Any]:
        return {"data": list(self.data), "model": self.model.to_dict(), "train": self.train.to_dict()}


__all__ = ["GraspModelConfig", "GraspTrainConfig", "GraspConfigError", "RunSpec", "ENCODERS", "CONDITIONS"]
