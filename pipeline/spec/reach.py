"""Reachability probes run before anything is written: the object-store output and the Ray cluster address.

A run that starts and then fails at its first write (or waits minutes on a dead cluster) wastes
the night; these checks are bounded in time and write nothing.
"""

from __future__ import annotations

import importlib
import os
import socket
import subprocess
import sys
import threading
from typing import Any
from urllib.parse import parse_qs, urlsplit

from pipeline.errors import SpecError
from pipeline.spec.fields import RAY_ADDRESS, URI_SCHEMES, check_ray_address, is_uri

#: seconds the reachability check of an object-store output may take (env override)
STORE_CHECK_TIMEOUT_S = 15.0

_FS_MODULES = {
    "s3": "pyarrow._s3fs",
    "gs": "pyarrow._gcsfs",
    "gcs": "pyarrow._gcsfs",
    "hdfs": "pyarrow._hdfs",
    "abfs": "pyarrow._azurefs",
    "abfss": "pyarrow._azurefs",
}

_PROBE = """
import sys
try:
    import pyarrow.fs as pafs
    fs, root = pafs.FileSystem.from_uri(sys.argv[1])
    info = fs.get_file_info(root.rstrip("/") or root)
    if info.type == pafs.FileType.File:
        print("it is a file, not a folder")
        sys.exit(1)
except BaseException as exc:
    print(f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"[:300])
    sys.exit(1)
"""


def _endpoint(scheme: str, location: str) -> tuple[str, int]:
    """(host, port) an object-store URI talks to."""
    u = urlsplit(location)
    query = {k: v[-1] for k, v in parse_qs(u.query).items()}

    def host_port(text: str, default_port: int) -> tuple[str, int]:
        if "://" not in text:
            text = "//" + text
        hp = urlsplit(text)
        return hp.hostname or "", hp.port or (443 if hp.scheme == "https" else 80 if hp.scheme == "http" else default_port)

    if scheme == "s3":
        override = query.get("endpoint_override") or os.environ.get("AWS_ENDPOINT_URL_S3") or os.environ.get("AWS_ENDPOINT_URL")
        if override:
            return host_port(override, 80 if query.get("scheme") == "http" else 443)
        return "s3.amazonaws.com", 443
    if scheme in ("gs", "gcs"):
        override = query.get("endpoint_override") or os.environ.get("STORAGE_EMULATOR_HOST")
        if override:
            return host_port(override, 80 if query.get("scheme") == "http" else 443)
        return "storage.googleapis.com", 443
    if scheme == "hdfs":
        return u.hostname or "", u.port or 8020
    # abfs://container@account.dfs.core.windows.net/path
    return (u.hostname or "").rpartition("@")[2], 443


def _reach(host: str, port: int, timeout: float) -> str | None:
    """Why ``host:port`` cannot be reached within ``timeout`` seconds (None when it can);
    name resolution runs in a daemon thread so a stuck resolver cannot hang the check."""
    if not host:
        return "no host in the URI"
    addrs: list[tuple[Any, ...]] = []
    errors: list[OSError] = []

    def resolve() -> None:
        try:
            addrs.extend(socket.getaddrinfo(host, port, type=socket.SOCK_STREAM))
        except OSError as exc:
            errors.append(exc)

    t = threading.Thread(target=resolve, daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        return f"name resolution of {host} took longer than {timeout:g} s"
    if errors:
        return f"cannot resolve {host} ({errors[0]})"
    last: OSError | None = None
    for family, socktype, proto, _, addr in addrs:
        s = socket.socket(family, socktype, proto)
        s.settimeout(timeout)
        try:
            s.connect(addr)
            return None
        except OSError as exc:
            last = exc
        finally:
            s.close()
    return f"cannot connect to {host}:{port} ({last})"


def check_output_location(location: str, *, timeout_s: float | None = None) -> None:
    """An object-store output (or run folder) must be usable now, not at the first write of a
    started run: the scheme is known, this pyarrow supports it, its endpoint answers, and the
    folder can be listed with the credentials at hand. Bounded in time (``timeout_s``, default
    ``RECAP_STORE_CHECK_TIMEOUT_S`` or 15 s); writes nothing. A local path or ``file://`` URI
    passes (the run store checks that it can be created)."""
    if not is_uri(location):
        return
    scheme = location.split("://", 1)[0].lower()
    if scheme not in URI_SCHEMES:
        raise SpecError(
            f"output {location}: unknown URI scheme {scheme!r}; use a local folder or {', '.join(s + '://' for s in URI_SCHEMES)}"
        )
    if scheme == "file":
        return
    if timeout_s is None:
        try:
            timeout_s = float(os.environ.get("RECAP_STORE_CHECK_TIMEOUT_S", STORE_CHECK_TIMEOUT_S))
        except ValueError:
            timeout_s = STORE_CHECK_TIMEOUT_S
    try:
        importlib.import_module(_FS_MODULES[scheme])
    except ImportError:
        raise SpecError(
            f"output {location}: this pyarrow cannot write {scheme}:// (no {scheme} support built in); use a local folder"
        ) from None
    host, port = _endpoint(scheme, location)
    why = _reach(host, port, min(timeout_s, 5.0))
    if why is not None:
        raise SpecError(f"output {location} cannot be used: {why}; check the network or use a local folder")
    try:
        r = subprocess.run(
            [sys.executable, "-c", _PROBE, location], capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL
        )
    except subprocess.TimeoutExpired:
        raise SpecError(
            f"output {location} cannot be used: no answer within {timeout_s:g} s "
            "(check credentials and network, or use a local folder)"
        ) from None
    except OSError as exc:
        raise SpecError(f"output {location} cannot be checked: {exc}") from None
    if r.returncode != 0:
        detail = (r.stdout.strip().splitlines() or r.stderr.strip().splitlines()[-1:] or ["unknown error"])[-1]
        raise SpecError(f"output {location} cannot be used: {detail}")


def check_ray_address_reachable(address: str | None, timeout_s: float = 5.0) -> None:
    """A ``host:port`` / ``ray://host:port`` cluster address must accept a TCP connection within
    ``timeout_s`` (``ray.init`` on a dead address retries for a long time); ``auto``/``local``
    and no address pass. Writes nothing."""
    if not address or address in ("auto", "local"):
        return
    check_ray_address(address)
    m = RAY_ADDRESS.match(address)
    assert m is not None
    why = _reach(m["host"].strip("[]"), int(m["port"]), timeout_s)
    if why is not None:
        raise SpecError(f"ray.address {address}: {why}; is the cluster up (ray status)?")
