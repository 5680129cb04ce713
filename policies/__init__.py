"""Baseline policies for CNTDeposit-v0: random, constant flow, scripted, SB3 loaders."""
