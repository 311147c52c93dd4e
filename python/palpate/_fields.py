"""Checking the fields of a parsed TOML document (scene files, touch scripts): each error names the
file and the field (``section.key``) and says what was expected, raised as the caller's error type."""
from __future__ import annotations

import math
from typing import Dict, Optional, Type

import numpy as np


class FieldChecker:
    """Field checks for the TOML document of the file ``name``; errors are ``error`` instances
    (``SceneError``, ``ScriptError``) with the message ``"<name>: <section.key>: <what>"``."""

    def __init__(self, name: str, error: Type[Exception]):
        self.name, self.error = name, error

    def err(self, key: str, msg: str) -> Exception:
        return self.error(f"{self.name}: {key}: {msg}")

    def _lookup(self, table: Dict, section: str, key: str, required: bool):
        """(label, present, value) of ``key``; a missing required key is an error."""
        label = f"{section}.{key}" if section else key
        if key not in table:
            if required:
                raise self.err(label, "missing (required)")
            return label, False, None
        return label, True, table[key]

    def number(self, table: Dict, section: str, key: str, default=None, positive=False, nonneg=False,
               integer=False, required=False):
        """A finite number (``integer``: a whole one), or ``default`` when absent."""
        label, present, v = self._lookup(table, section, key, required)
        if not present:
            return default
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(label, f"must be a {'whole ' if integer else ''}number, got {v!r}")
        if integer and not isinstance(v, int):
            raise self.err(label, f"must be a whole number, got {v!r}")
        if not math.isfinite(v):
            raise self.err(label, f"must be finite, got {v!r}")
        if positive and not v > 0:
            raise self.err(label, f"must be positive, got {v!r}")
        if nonneg and v < 0:
            raise self.err(label, f"must not be negative, got {v!r}")
        return v

    def vec3(self, table: Dict, section: str, key: str, default=None, required=False,
             nonzero=False) -> Optional[np.ndarray]:
        """A list of 3 finite numbers as a (3,) array (``nonzero``: not all zero), or ``default``."""
        label, present, v = self._lookup(table, section, key, required)
        if not present:
            return default
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            raise self.err(label, f"must be a list of 3 finite numbers [x, y, z], got {v!r}")
        a = np.array(v, dtype=np.float64)
        if nonzero and not np.linalg.norm(a) > 0:
            raise self.err(label, "must not be zero")
        return a

    def table(self, doc: Dict, key: str, required=False) -> Dict:
        """The sub-table ``key`` (``{}`` when absent and not required)."""
        if key not in doc:
            if required:
                raise self.err(key, "missing table (required)")
            return {}
        v = doc[key]
        if not isinstance(v, dict):
            raise self.err(key, f"must be a table, got {v!r}")
        return v

    def known(self, table: Dict, section: str, allowed) -> None:
        """Refuse keys of ``table`` not in ``allowed``."""
        for k in table:
            if k not in allowed:
                where = f"{section}.{k}" if section else k
                raise self.err(where, f"unknown key (expected one of: {', '.join(sorted(allowed))})")
