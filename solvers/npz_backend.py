"""An emcee backend that persists the chain to an ``.npz`` file.

:class:`NpzBackend` is emcee's in-memory :class:`emcee.backends.Backend` (so every reader of a
backend works: ``get_chain(discard=, thin=, flat=)``, ``get_log_prob``, ``accepted``,
``get_autocorr_time``, ``iteration``) that also writes its arrays, atomically, to one ``.npz``
file every ``flush_every`` steps and on :meth:`flush`; :meth:`NpzBackend.load` reads such a file
back. It stands in for :class:`emcee.backends.HDFBackend` without the h5py/HDF5 dependency: the
chains here are small (budget x parameters floats, a few MB at most), so rewriting the whole file
on a flush costs little, and a crash loses at most ``flush_every`` steps.

File keys (as HDFBackend's datasets): ``chain`` (steps, walkers, dimensions) in the sampler's
coordinates, ``log_prob`` (steps, walkers), ``accepted`` (walkers,), ``iteration``, plus the
``metadata`` arrays given to the constructor (e.g. ``names`` and ``scale``:
physical = chain x scale).
A file with only ``chain`` and ``log_prob`` (and optional metadata) loads too: ``iteration`` is then
the chain length and ``accepted`` zero.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from emcee.backends import Backend

_OWN_KEYS = ("chain", "log_prob", "accepted", "iteration")


class NpzBackend(Backend):
    """emcee backend in memory, persisted to ``path`` (see the module docstring)."""

    def __init__(self, path, *, flush_every: int = 10, metadata: dict | None = None, dtype=None):
        super().__init__(dtype=dtype)
        self.path = Path(path)
        self.flush_every = max(1, int(flush_every))
        self.metadata = {k: np.asarray(v) for k, v in (metadata or {}).items()}
        clash = set(self.metadata) & set(_OWN_KEYS)
        if clash:
            raise ValueError(f"metadata keys {sorted(clash)} are reserved for the chain")

    def save_step(self, state, accepted):
        super().save_step(state, accepted)
        if self.iteration % self.flush_every == 0:
            self.flush()

    def flush(self) -> Path:
        """Write the steps so far (and the metadata) to :attr:`path` atomically; returns the
        path."""
        if not self.initialized:
            raise ValueError("the backend holds no chain yet")
        n = self.iteration
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "wb") as fh:
            np.savez(
                fh,
                chain=self.chain[:n],
                log_prob=self.log_prob[:n],
                accepted=self.accepted,
                iteration=np.int64(n),
                **self.metadata,
            )
        os.replace(tmp, self.path)
        return self.path

    @classmethod
    def load(cls, path) -> NpzBackend:
        """The backend stored in ``path``, ready for reading (or for an ``EnsembleSampler`` to
        continue)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path} does not exist")
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        if "chain" not in data or "log_prob" not in data:
            raise ValueError(f"{path} holds no chain (keys: {', '.join(sorted(data))})")
        chain = np.asarray(data.pop("chain"), float)
        log_prob = np.asarray(data.pop("log_prob"), float)
        n = int(data.pop("iteration", chain.shape[0]))
        accepted = data.pop("accepted", None)
        backend = cls(path, metadata=data)
        backend.reset(chain.shape[1], chain.shape[2])
        backend.chain, backend.log_prob, backend.iteration = chain[:n], log_prob[:n], n
        if accepted is not None:
            backend.accepted = np.asarray(accepted, backend.dtype)
        return backend
