"""A calibrated subject: the actor's bones and where each marker sits on them (docs/design.md, "Data contracts").

Each joint is fixed in its parent's bone frame (``offsets``: a BVH OFFSET, so the bone's length is its
norm); each marker rides one bone at a fixed offset in that bone's frame. Written by ``mocap
calibrate`` and read by the fit (``mocap solve --subject``, the skeleton_fit node), so a studio
calibrates an actor once and reuses the file, as with Vicon's VSK or QTM's skeleton calibration.

```yaml
format: mocap-subject/1
profile: cmu41
frames: 3000              # frames the calibration learned from
converged: true
bones:                    # joint: its parent and its offset in the parent's frame (metres)
  spine0: {parent: pelvis, offset: [0.0, 0.02, 0.08], length_m: 0.0825,
           rest: [0.1, 0.0, 0.0]}    # its typical rotation in the parent's frame (a rotation vector)
markers:                  # label: its bone, its offset in that bone's frame, its spread there (mm)
  LELB: {bone: shoulder_l, offset: [0.03, 0.28, -0.01], spread_mm: 4.1}
unassigned: [StartG]      # labels that moved with no bone (props, the floor)
from_motion: [knee_l]     # joints no landmark located, found from the take's motion (when there are)
```
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from mocap_core.skeleton import INDEX, JOINTS, PARENT

FORMAT = "mocap-subject/1"


class SubjectError(Exception):
    pass


@dataclass
class Subject:
    profile: str
    offsets: np.ndarray          # (J, 3) each joint in its parent's bone frame; the root's is zero
    known: np.ndarray            # (J,) bool: the joints the calibration located (others are not solved)
    labels: list[str]            # every marker the calibration saw, by label
    marker_bone: np.ndarray      # (M,) joint index of the bone each marker rides, -1 = none
    marker_offsets: np.ndarray   # (M, 3) in that bone's frame
    spread_m: np.ndarray         # (M,) how far the marker strayed from its offset while calibrating (robust)
    frames: int = 0
    converged: bool = False
    rest: np.ndarray = field(default=None)  # (J, 3, 3) each bone's typical rotation in its parent's frame
    from_motion: tuple[str, ...] = ()       # joints no landmark located, found from the take's motion

    def __post_init__(self):
        if self.rest is None:
            self.rest = np.tile(np.eye(3), (len(JOINTS), 1, 1))

    def lengths(self) -> np.ndarray:
        """(J,) each joint's distance from its parent (the bone's length; 0 for the root)."""
        return np.linalg.norm(self.offsets, axis=1)

    def marker_index(self, labels: list[str]) -> np.ndarray:
        """For a stream's labels, the row of each in this subject (-1 for a label it does not know)."""
        rows = {label: i for i, label in enumerate(self.labels)}
        return np.array([rows.get(label, -1) for label in labels], np.int64)

    def save(self, path: str | Path) -> None:
        bones = {}
        for j, name in enumerate(JOINTS):
            if PARENT[name] is None or not self.known[j]:
                continue
            bones[name] = {"parent": PARENT[name], "offset": _round(self.offsets[j]),
                           "length_m": round(float(np.linalg.norm(self.offsets[j])), 5),
                           "rest": _round(rotation_vector_np(self.rest[j]))}
        markers = {label: {"bone": JOINTS[b], "offset": _round(self.marker_offsets[i]),
                           "spread_mm": round(float(self.spread_m[i] * 1000), 1)}
                   for i, (label, b) in enumerate(zip(self.labels, self.marker_bone)) if b >= 0}
        doc = {"format": FORMAT, "profile": self.profile, "frames": int(self.frames), "converged": bool(self.converged),
               "bones": bones, "markers": markers,
               "unassigned": [label for label, b in zip(self.labels, self.marker_bone) if b < 0],
               **({"from_motion": list(self.from_motion)} if self.from_motion else {})}
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=110))


def _round(v) -> list[float]:
    return [round(float(x), 5) for x in v]


def rotation_vector_np(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(R).as_rotvec()


def load_subject(path: str | Path) -> Subject:
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise SubjectError(f"subject file {path} not found (write one with: mocap calibrate TAKE --profile P "
                           f"-o {path.name})") from None
    except yaml.YAMLError as e:
        raise SubjectError(f"subject file {path}: not valid YAML ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SubjectError(f"subject file {path}: not a subject file (expected format: {FORMAT})")
    from scipy.spatial.transform import Rotation
    n = len(JOINTS)
    offsets, known, rest = np.zeros((n, 3)), np.zeros(n, bool), np.tile(np.eye(3), (n, 1, 1))
    known[0] = True
    try:
        for name, bone in (doc.get("bones") or {}).items():
            if name not in INDEX:
                raise SubjectError(f"subject file {path}: unknown joint {name!r} (joints: {', '.join(JOINTS)})")
            j = INDEX[name]
            offsets[j] = np.asarray(bone["offset"], float).reshape(3)
            rest[j] = Rotation.from_rotvec(np.asarray(bone.get("rest", [0, 0, 0]), float)).as_matrix()
            known[j] = True
        labels, bones, marker_offsets, spread = [], [], [], []
        for label, m in (doc.get("markers") or {}).items():
            if m["bone"] not in INDEX:
                raise SubjectError(f"subject file {path}: marker {label}: unknown bone {m['bone']!r}")
            labels.append(str(label))
            bones.append(INDEX[m["bone"]])
            marker_offsets.append(np.asarray(m["offset"], float).reshape(3))
            spread.append(float(m.get("spread_mm", 0.0)) / 1000)
        for label in doc.get("unassigned") or []:
            labels.append(str(label))
            bones.append(-1)
            marker_offsets.append(np.zeros(3))
            spread.append(np.nan)
    except (KeyError, TypeError, ValueError) as e:
        raise SubjectError(f"subject file {path}: malformed entry ({e!r})") from None
    if not np.isfinite(offsets).all() or not labels:
        raise SubjectError(f"subject file {path}: needs finite bone offsets and at least one marker")
    return Subject(str(doc.get("profile", "")), offsets, known, labels, np.array(bones, np.int64),
                   np.array(marker_offsets).reshape(-1, 3), np.array(spread), int(doc.get("frames", 0)),
                   bool(doc.get("converged", False)), rest, tuple(map(str, doc.get("from_motion") or ())))
