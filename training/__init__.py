"""Training, evaluation and sweep scripts for CNTDeposit-v0."""
