"""The morphology encodings a VAE can be trained on, by name (a model's config names its own).

``reference66``: the paper's 66-D layout (:mod:`ohra.learn.encoding`; thumb mount as Euler rpy,
zeros for absent parts), kept so that models trained on it load and compare.
``rot6d70``: the 70-D layout of :mod:`ohra.learn.encoding_rot6d` (right-hand form plus a left flag,
thumb mount as rot6d, stand-ins for absent parts, plausible decoding), the default.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ohra.errors import ParamsError
from ohra.learn import encoding as ref
from ohra.learn import encoding_rot6d as r6
from ohra.learn.geometry import matrix_from_rot6d
from ohra.transforms import rpy_to_matrix

DEFAULT_ENCODING = "rot6d70"


@dataclass(frozen=True)
class Encoding:
    """Layout and functions of one encoding (slices index the encoded vector)."""

    name: str
    dim: int
    cont: slice
    axis1: slice
    axis2: slice
    flags: slice
    rotation: slice  # the thumb mount's block inside the encoding (rpy or rot6d)
    left: slice | None  # the left-hand flag (None: the encoding keeps left hands as they are)
    cont_names: tuple[str, ...]
    encode_vectors: Callable[..., np.ndarray]  # (v82 (N, 82), warn) -> (N, dim), raw units
    decode_vectors: Callable[..., np.ndarray]  # (x (N, dim), limits) -> valid (N, 82)
    thumb_matrix: Callable[[np.ndarray], np.ndarray]  # rotation block (N, k) -> (N, 3, 3)

    @property
    def cont_dim(self) -> int:
        return self.cont.stop - self.cont.start

    @property
    def binary(self) -> slice:
        """The 0/1 block the presence head predicts: the 22 joint flags, then the left flag if any."""
        return slice(self.flags.start, self.left.stop if self.left is not None else self.flags.stop)

    def groups(self) -> dict[str, tuple[slice, str]]:
        """Continuous parameter groups (slices into the continuous block) and units, for reports."""
        g = {k: v for k, v in ref.CONT_GROUPS.items() if k != "thumb_rpy"}
        rot = slice(self.rotation.start - self.cont.start, self.rotation.stop - self.cont.start)
        g["thumb_rpy" if self.name == "reference66" else "thumb_rot6d"] = (rot, "rad" if self.name == "reference66" else "1")
        return g


ENCODINGS: dict[str, Encoding] = {
    "reference66": Encoding("reference66", ref.ENCODING_DIM, ref.CONT, ref.AXIS1, ref.AXIS2, ref.FLAGS, slice(29, 32), None,
                            ref.CONT_NAMES, ref.encode_vectors, ref.decode_vectors, rpy_to_matrix),
    "rot6d70": Encoding("rot6d70", r6.ENCODING_DIM, r6.CONT, r6.AXIS1, r6.AXIS2, r6.FLAGS, r6.ROT6D, r6.LEFT,
                        r6.CONT_NAMES, r6.encode_vectors, r6.decode_vectors, lambda x: matrix_from_rot6d(x, "zx")),
}


def get_encoding(name: Any) -> Encoding:
    """The :class:`Encoding` called ``name``; :class:`ParamsError` naming the known ones otherwise."""
    if isinstance(name, Encoding):
        return name
    try:
        return ENCODINGS[str(name)]
    except KeyError:
        raise ParamsError(f"unknown morphology encoding {name!r}; known: {', '.join(ENCODINGS)}") from None
