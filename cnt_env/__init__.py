"""cnt_env: carbon-nanotube deposition with discrete elastic rods, as a Gymnasium env.

The simulator runs in the dimensionless units of ``cnt_env.units``; SI appears
only there and at the command line (``cnt-sim``, also ``python -m cnt_env``).
"""

# The gymnasium registration of CNTDeposit-v0 will go here once cnt_env.env exists.

__version__ = "0.1.0"

__all__ = ["__version__"]
