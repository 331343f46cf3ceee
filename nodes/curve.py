"""ZeroMQ CURVE (authenticated, encrypted) links between nodes, with keys read from files.

Key directory layout (make one with ``mocap keys generate DIR``):

    DIR/server.key_secret   publishers' key pair (every node's XPUB socket is a CURVE server)
    DIR/server.key          its public half, which subscribers need
    DIR/client.key_secret   subscribers' key pair
    DIR/authorized/         public keys of the clients allowed to subscribe (client.key is put there)

A subscriber whose key is not in ``authorized/`` is refused by the ZAP handler at the handshake, so it
receives nothing. Copy the directory to every host of a multi-host graph (keep the secrets secret).
"""
from __future__ import annotations

import logging
from pathlib import Path

import zmq
import zmq.auth
from zmq.auth.thread import ThreadAuthenticator


log = logging.getLogger("mocap.curve")


class CurveError(Exception):
    pass


def generate(directory: str | Path) -> Path:
    """A key directory that only its owner can read (folders 0700, secrets 0600): a secret another local user can
    read lets them receive the stream."""
    d = Path(directory)
    (d / "authorized").mkdir(parents=True, exist_ok=True)
    for folder in (d, d / "authorized"):
        folder.chmod(0o700)
    zmq.auth.create_certificates(d, "server")
    client_public, _ = zmq.auth.create_certificates(d, "client")
    (d / "authorized" / "client.key").write_bytes(Path(client_public).read_bytes())
    for secret in d.glob("*.key_secret"):
        secret.chmod(0o600)
    return d


def _load(path: Path, secret: bool):
    if not path.exists():
        raise CurveError(f"CURVE key file {path} not found (make keys with `mocap keys generate DIR`)")
    public, secret_key = zmq.auth.load_certificate(str(path))
    if secret and secret_key is None:
        raise CurveError(f"{path} holds no secret key")
    if secret and path.stat().st_mode & 0o077:
        log.warning("CURVE secret %s can be read by other users: chmod 600 %s (and chmod 700 its folder)", path, path)
    return public, secret_key


def secure_publisher(sock: zmq.Socket, keys: str) -> None:
    public, secret = _load(Path(keys) / "server.key_secret", True)
    sock.curve_secretkey, sock.curve_publickey, sock.curve_server = secret, public, True


def secure_subscriber(sock: zmq.Socket, keys: str) -> None:
    public, secret = _load(Path(keys) / "client.key_secret", True)
    server_public, _ = _load(Path(keys) / "server.key", False)
    sock.curve_secretkey, sock.curve_publickey, sock.curve_serverkey = secret, public, server_public


def start_authenticator(ctx: zmq.Context, keys: str) -> ThreadAuthenticator:
    """Only clients whose public key is in keys/authorized may subscribe to this process's sockets."""
    auth = ThreadAuthenticator(ctx)
    auth.start()
    auth.configure_curve(domain="*", location=str(Path(keys) / "authorized"))
    return auth
