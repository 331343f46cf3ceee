"""Stage 4: IK gap filling for one limb (thesis 3.6).

``limb: torso`` reads ``skeleton/localized`` and publishes the whole skeleton with the torso filled
on ``skeleton/torso``; the four limb nodes read ``skeleton/torso`` in parallel processes and each
publishes its joints on ``skeleton/limb/<limb>``.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from messages import LimbSolution, MarkerFrame, SkeletonFrame
from mocap_core.fill_options import FillOptions
from mocap_core.gapfill import LimbFiller
from mocap_core.ik.constraints import load_constraints
from mocap_core.ik.solvers import SOLVERS, SolverParams
from mocap_core.skeleton import LIMBS
from mocap_core.marker_gate import MarkerGate
from mocap_core.presets import PRESET_HELP, Preset, with_preset
from mocap_core.profiles import strip_prefix
from mocap_core.warmup import fill_parts
from nodes.runtime import Node
from nodes.skeleton_codec import from_message, to_message


MARKER_FRAMES_KEPT = 256


class Params(FillOptions):
    """The limb, the solver and its limits, and the fills beyond the thesis (FillOptions)."""
    model_config = ConfigDict(extra="forbid")
    limb: Literal[tuple(LIMBS)]  # type: ignore[valid-type]  (the stages of mocap_core.skeleton)
    preset: Preset = Field("studio", description=PRESET_HELP)
    solver: str = Field("ccd", description=f"one of {', '.join(SOLVERS)}")
    constraints: bool = True
    constraints_file: str | None = None
    max_iterations: int = Field(140, ge=1)
    stop_distance_m: float = Field(0.01, gt=0)
    subject: str | None = Field(None, description="a subject file (mocap calibrate) whose bones the rigid chain "
                                "keeps, fitted to the markers it places on the limb (read from markers/raw); "
                                "without one it keeps the lengths learned from the stream")

    @model_validator(mode="before")
    @classmethod
    def _preset(cls, values):
        limb = values.get("limb") if isinstance(values, dict) else None
        return with_preset("ik", values, leave=FillOptions.idle_on(limb))

    @model_validator(mode="after")
    def _acts_on_the_limb(self):
        self.refuse_idle(self.limb)
        return self


class IkGapfill(Node):
    kind = "ik_gapfill"
    Params = Params
    # (its topics depend on the limb: inputs and outputs are its declaration)

    @classmethod
    def inputs(cls, params):
        # the torso reads the localized skeleton; the limbs read the torso's output; with a subject, the markers too
        inputs = {"skeleton/localized" if params.limb == "torso" else "skeleton/torso": SkeletonFrame}
        return inputs | ({"markers/raw": MarkerFrame} if params.subject else {})

    @classmethod
    def outputs(cls, params):
        if params.limb == "torso":
            return {"skeleton/torso": SkeletonFrame}
        return {f"skeleton/limb/{params.limb}": LimbSolution}

    @classmethod
    def kernels(cls, params):
        # (a subject's markers: gated, then the fit's solve)
        return fill_parts(params) + (("fit", "markers") if params.subject else ())

    def setup(self) -> None:
        p = self.params
        self.filler = LimbFiller(p.limb, p.solver, SolverParams(p.max_iterations, p.stop_distance_m, p.constraints),
                                 load_constraints(p.constraints_file), FillOptions.of(p))
        self.names = list(LIMBS[p.limb])
        self.subject, self.labels = None, []
        self.gate = MarkerGate()  # (as the offline solve drops them)
        self.markers: dict[int, np.ndarray] = {}  # frame -> its markers, until its skeleton comes
        self.held: SkeletonFrame | None = None     # a skeleton that came before its markers
        self.unmatched = 0                          # skeletons that came before any markers
        if p.subject:
            from mocap_core.fit.subject import load_subject
            self.subject = load_subject(p.subject)
            self.filler.use(self.subject)

    def on_message(self, topic, msg) -> None:
        if topic == "markers/raw":
            self._keep_markers(msg)
            if self.held is not None and self.held.header.frame <= msg.header.frame:
                self._solve(self._release())
            return
        if self.held is not None:  # (its markers never came)
            self._solve(self._release())
        if self.subject is not None and msg.header.frame not in self.markers:
            if self.labels or self.unmatched < MARKER_FRAMES_KEPT:
                # its markers were sent before it but come by another publisher's socket: they are on their way
                self.unmatched += not self.labels
                self.held = msg
                return
            if self.unmatched == MARKER_FRAMES_KEPT:
                self.unmatched += 1
                self.log.warning("no markers on markers/raw: each limb is fitted to its joints alone")
        self._solve(msg)

    def _release(self) -> SkeletonFrame:
        held, self.held = self.held, None
        return held

    def _solve(self, msg: SkeletonFrame) -> None:
        markers = self.markers.pop(msg.header.frame, None)
        for older in [f for f in self.markers if f < msg.header.frame]:  # (frames whose skeleton never came)
            del self.markers[older]
        pos, frames, status = from_message(msg)
        stats = self.filler.fill(pos, frames, status, msg.header.capture_time_s, markers)
        if self.params.limb == "torso":
            self.ctx.publish("skeleton/torso", to_message(pos, frames, status), source=msg)
            return
        idx = self.filler.joints
        self.ctx.publish(f"skeleton/limb/{self.params.limb}", LimbSolution(
            header=LimbSolution.make_header(), limb=self.params.limb, joints=self.names,
            positions=pos[idx].astype(np.float32), rotations=frames[idx].astype(np.float32),
            status=status[idx], solver=self.params.solver, iterations=stats.iterations,
            residual_m=stats.residual_m, solve_time_us=stats.solve_time_us), source=msg)

    def _keep_markers(self, msg: MarkerFrame) -> None:
        """A frame's markers, for the rigid chain's fit when the frame's skeleton comes (most often the markers come
        first: the skeleton passed through the stages before this one)."""
        if msg.labels != self.labels:  # the first frame, or a new marker set: the subject's names for its labels
            self.labels = list(msg.labels)
            known = set(self.subject.labels)
            names = [x if x in known else strip_prefix(x) for x in self.labels]
            self.filler.use(self.subject, names)
            if not known.intersection(names):
                self.log.warning("none of the stream's %d labels is a marker of the subject (%s): each limb is "
                                 "fitted to its joints alone", len(names), self.params.subject)
            self.gate = MarkerGate()
        self.markers[msg.header.frame], _ = self.gate.filter(msg.positions, msg.header.capture_time_s)
        while len(self.markers) > MARKER_FRAMES_KEPT:  # (a stream whose skeletons stopped)
            del self.markers[next(iter(self.markers))]
