"""A VMC receiver for tests: python-osc's blocking UDP server (datagrams handled one at a time, in order),
collecting each frame as a receiver sees it, and forward kinematics as EVMC4U applies it."""
from __future__ import annotations

import socket
import threading

import numpy as np
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer

from mocap_core.ik.kernels import quats_to_frames
from mocap_core.rig import BONE_PARENT, BONES


class _Server(BlockingOSCUDPServer):
    def verify_request(self, request, client_address):
        self.sizes.append(len(request[0]))
        return super().verify_request(request, client_address)


class VmcReceiver:
    """Frames start at /VMC/Ext/Root/Pos; each holds the root (p, q), every bone's (p, q), T and OK."""

    def __init__(self):
        self.frames: list[dict] = []
        disp = Dispatcher()
        disp.map("/VMC/Ext/Root/Pos", self._root)
        disp.map("/VMC/Ext/Bone/Pos", self._bone)
        disp.map("/VMC/Ext/T", lambda a, t: self._put("T", t))
        disp.map("/VMC/Ext/OK", lambda a, *v: self._put("OK", v))
        self.server = _Server(("127.0.0.1", 0), disp)
        self.server.sizes = []
        # UDP: a receiver that falls behind on a loaded host loses datagrams once the socket's buffer is full
        self.server.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    @property
    def sizes(self) -> list[int]:
        return self.server.sizes

    def _root(self, address, name, *v):
        self.frames.append({"root": (np.array(v[:3]), np.array(v[3:7])), "bones": {}})

    def _bone(self, address, name, *v):
        if self.frames:
            self.frames[-1]["bones"][name] = (np.array(v[:3]), np.array(v[3:7]))

    def _put(self, key, value):
        if self.frames:
            self.frames[-1][key] = value

    def complete(self) -> list[dict]:
        return [f for f in self.frames if len(f["bones"]) == len(BONES) and "OK" in f]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def forward_kinematics(frame: dict) -> tuple[np.ndarray, np.ndarray]:
    """World positions and rotations (B, 3) / (B, 3, 3), Unity frame, of one received frame: the root
    transform, then each bone's local position and rotation under its parent's."""
    root_p, root_q = frame["root"]
    root_r = quats_to_frames(root_q[None].astype(float))[0]
    pos, world = np.zeros((len(BONES), 3)), np.zeros((len(BONES), 3, 3))
    for b, p in enumerate(BONE_PARENT):
        lp, lq = frame["bones"][BONES[b]]
        local = quats_to_frames(lq[None].astype(float))[0]
        parent_p, parent_r = (root_p, root_r) if p < 0 else (pos[p], world[p])
        pos[b] = parent_p + parent_r @ lp
        world[b] = parent_r @ local
    return pos, world
