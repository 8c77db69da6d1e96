"""On-robot runtime: ONNX VelocityNet policy, subgoal-switching controller, ZeroMQ daemon.

Imports only numpy, onnxruntime, pyzmq and the standard library, so that `pip install vtr-mpc`
(no extras) is all a robot board needs.
"""

__version__ = "0.1.0"
