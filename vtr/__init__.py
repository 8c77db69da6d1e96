"""vtr: visual teach & repeat with an offline deep-MPC VelocityNet.

The libraries live in the repository's top-level folders (``runtime/``, ``sim2d/``, ``training/``, ``export/``,
``benchmarks/``) and are installed as ``vtr.runtime``, ``vtr.sim2d``, ... through setuptools' ``package-dir``
mapping, so that an install adds one top-level name, ``vtr``, to site-packages and never a generic ``runtime``.

In a source checkout that is not installed (``PYTHONPATH=.``), the same names resolve because this package's
search path is extended with the checkout's root. That happens only when the folder above holds our
``pyproject.toml``: an installed copy never looks outside itself.
"""

from __future__ import annotations

from pathlib import Path

__version__ = "0.2.0"

_root = Path(__file__).resolve().parent.parent
if (_root / "pyproject.toml").is_file() and (_root / "runtime" / "__init__.py").is_file():
    __path__.append(str(_root))  # noqa: F821 - a package's __path__ is defined by the import system
