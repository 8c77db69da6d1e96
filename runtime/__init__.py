"""On-robot runtime: ONNX VelocityNet policy, subgoal-switching controller, ZeroMQ daemon.

Imports only numpy, onnxruntime, pyzmq and the standard library, so that `pip install vtr-mpc`
(no extras) is all a robot board needs.
"""

from vtr import __version__ as __version__  # one source: vtr/__init__.py
