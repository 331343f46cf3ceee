"""Several actors in one stream: each actor's markers on topics of its own, for a solving pipeline per actor.

QTM and Vicon name a subject's markers with the subject's name in front ("actor1:LASI"). A source given
``actors`` publishes the whole stream on ``markers/raw`` as always, and each actor's share of it on
``mocap/<actor>/markers/raw`` and ``mocap/<actor>/markers/set`` (the namespace the launcher gives that actor's
pipeline). An actor listed but not in the stream, or who leaves it, is said once in the log; their pipeline
waits, and goes on when they come back. A subject in the stream that the list does not name is said once too.
"""
from __future__ import annotations

import logging

import numpy as np

from messages import MarkerFrame, MarkerSet, Message, SkeletonFrame
from mocap_core.profiles import actor_of


def actor_topics(actors: list[str]) -> dict[str, type[Message]]:
    """The topics a source splitting for ``actors`` writes besides the whole stream's."""
    return {f"mocap/{a}/{t}": kind for a in actors for t, kind in (("markers/raw", MarkerFrame),
                                                                    ("markers/set", MarkerSet))}


def skeletons_of(actors: list[str]) -> dict[str, type[Message]]:
    """What an output that shows everyone reads: each actor's ``skeleton/solved``."""
    return {f"mocap/{a}/skeleton/solved": SkeletonFrame for a in actors}


def actor_in(topic: str) -> str:
    """The actor whose topic this is ("mocap/alice/skeleton/solved" -> "alice"; "" for a stream of one)."""
    return topic.split("/")[1] if topic.startswith("mocap/") else ""


class ActorSplit:
    """Publishes a source's ``markers/raw`` and ``markers/set`` whole and, for each listed actor, their share."""

    def __init__(self, ctx, actors: list[str], log: logging.Logger):
        self.ctx, self.actors, self.log = ctx, list(actors), log
        self.labels: list[str] | None = None
        self.columns: dict[str, np.ndarray] = {}

    def publish(self, topic: str, msg: MarkerFrame | MarkerSet) -> None:
        self.ctx.publish(topic, msg)
        if not self.actors:
            return
        if msg.labels != self.labels:
            self._learn(msg.labels)
        for actor, cols in self.columns.items():
            part = {"header": msg.header.model_copy(), "labels": [msg.labels[i] for i in cols]}
            if isinstance(msg, MarkerFrame):
                part.update(positions=msg.positions[cols], flags=msg.flags[cols])
            self.ctx.publish(f"mocap/{actor}/{topic}", msg.model_copy(update=part))

    def _learn(self, labels: list[str]) -> None:
        self.labels = list(labels)
        owners = np.array([actor_of(x) for x in labels])
        self.columns = {a: np.flatnonzero(owners == a) for a in self.actors if (owners == a).any()}
        absent = [a for a in self.actors if a not in self.columns]
        others = sorted(set(owners) - set(self.actors) - {""})
        self.log.info("actors in the stream: %s", ", ".join(f"{a} ({len(c)} markers)" for a, c in
                                                            self.columns.items()) or "none of those listed")
        if absent:
            self.log.warning("no markers of %s in the stream (labels 'NAME:MARKER'); their pipeline waits for them",
                             ", ".join(absent))
        if others:
            self.log.warning("the stream also holds %s, which the launch file's actors: does not list (not solved)",
                             ", ".join(others))
