"""Offline commands register their sub-parsers here (each lives in its own module)."""
from __future__ import annotations


def register(sub) -> None:
    from mocap_cli import bag_cmd, calibrate, check, compose, demo, eval_cmd, profile_cmd, qtm_sim, solve

    solve.add_parser(sub)
    calibrate.add_parser(sub)
    check.add_parser(sub)
    profile_cmd.add_parser(sub)
    compose.add_parser(sub)
    bag_cmd.add_parser(sub)
    qtm_sim.add_parser(sub)
    eval_cmd.add_parser(sub)
    demo.add_parser(sub)
