"""The RL task on top of the simulator: ``CNTDeposit-v0`` and what it is made of.

* ``env``: the Gymnasium class (translates actions and observations only);
* ``targets``: circuit routes and their families, with the held-out set.
"""
