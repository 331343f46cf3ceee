"""The `mocap` command line: launcher, topic and node tools, offline commands."""
