"""The deposition simulator: forces attached from above to the DER kernels of ``rod/``.

* ``forces``: vdW contact pull (paper eq. 1) and rarefied drag (paper eq. 2), with
  their Jacobians, assembled into the band;
* ``stepper``: :class:`Rod` (owns the buffers) and the implicit-Euler Newton stepper;
* ``substrate``: flat sticky and stepped (critical curvature) substrates;
* ``deposition``: :class:`DepositionSim` (owns the state: contact, injection, deletion,
  the trace, snapshots);
* ``warmstart``: post-transient states cached on disk per configuration.

Nothing here imports the task, runs, replay or CLI layers above it.
"""
