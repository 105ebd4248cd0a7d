"""The scenario runner: the whole chain (simulated stations -> centre -> VRS -> onboard unit) in one
process, faster than real time, compared with the simulator's truth (`augnet scenario run`)."""
