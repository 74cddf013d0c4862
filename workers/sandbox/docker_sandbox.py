"""The docker sandbox: one container of a locally built image per episode.

Why the Docker SDK for Python (``docker``) and not SWE-ReX: SWE-ReX runs its own server inside
the image (it must be installed there, and its deployments pull images from a registry), while
the SDK talks to the local daemon directly over its socket, needs nothing inside the image but
bash and coreutils, and is what SWE-bench's own evaluation harness uses to run its containers.

The container: ``spec.image`` with ``docker-init`` as PID 1 (it reaps what the wrapper kills) and
``sleep infinity`` as the keeper; ``network_mode="none"`` unless ``limits.network``; memory (no
swap) and pids limits; all capabilities dropped but the few a root shell needs for files and
processes, and ``no-new-privileges``; the environment is only ``PATH``/``HOME``/``LANG`` and
``spec.env`` (the Docker daemon never passes the host's variables, so no API key is inside). The
repository is cloned on the host at ``base_commit`` (:mod:`workers.sandbox.repo_copy`), tarred
and copied in with ``put_archive`` at ``spec.workdir``, ``.git`` included, and git gets a user. An image that holds
the repository itself (``spec.repo_path`` None: the SWE-bench harness's images, ``/testbed``) gets
nothing copied: git gets its user there, and the repository's HEAD must be ``spec.base_commit`` or
the harness's own commit on top of it (:func:`image_commit`).

Disk: every writable place is bounded (:mod:`workers.sandbox.docker_disk`): a quota on the
writable layer where the storage driver has one, else a read-only root filesystem with the
repository folder and the scratch folders (``/tmp``, ``/var/tmp``, ``$HOME``, ``/run``) as
size-limited tmpfs mounts, the repository streamed in with ``tar`` on an exec's stdin. The
repository folder is also measured with ``du`` every second while a command runs (it is killed
when over ``limits.disk_bytes``) and after each command (reported in the result), and ``ulimit
-f`` caps single files; see :mod:`workers.sandbox.wrapper`. Files are read and written by a
script in the container that resolves every path there (:mod:`workers.sandbox.docker_files`).

Commands: ``bash -c`` through the wrapper (``timeout -s KILL`` inside, output cut inside, strays
killed after each command), plus a host-side guard: when the exec has not returned a few seconds
after the timeout (the container is wedged, e.g. no pid left to run anything), every process in
it is killed, and if even that cannot run, the container is restarted (its files survive).
"""

from __future__ import annotations

import concurrent.futures
import logging
import posixpath
import secrets
import tarfile
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, NoReturn

from workers.sandbox.base import CommandResult, FileSlice, Sandbox, SandboxError, SandboxKind, SandboxSpec
from workers.sandbox.docker_disk import image_tree, populate, quota_size, storage_quota_supported, tmpfs_mounts
from workers.sandbox.docker_files import FILE_OP, check_path, exec_with_stdin, parse_lines, parse_read, raise_for
from workers.sandbox.repo_copy import clone_at
from workers.sandbox.wrapper import WRAPPER, parse

log = logging.getLogger(__name__)

BASE_ENV: Mapping[str, str] = {
    "PATH": "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
    "HOME": "/root",
    "LANG": "C.UTF-8",
}
#: what a root shell needs for files and processes; everything else (net admin, mknod, ptrace,
#: raw sockets, mount...) is dropped
CAPS = ["CHOWN", "DAC_OVERRIDE", "FOWNER", "FSETID", "KILL", "SETGID", "SETUID"]
#: seconds after a command's timeout before the host-side guard steps in
GUARD_GRACE_S = 5.0
GIT_USER = ("recap-eval sandbox", "sandbox@recap-eval.invalid")


def docker_client(timeout_s: float = 120.0) -> Any:
    """A client of the local daemon; SandboxError (one line, how to start it) when unreachable."""
    import docker
    import docker.errors

    try:
        client = docker.from_env(timeout=int(timeout_s))
        client.ping()
    except docker.errors.DockerException as e:
        raise SandboxError(
            f"the Docker daemon is unreachable ({str(e).splitlines()[0][:160]}); start it "
            "(`sudo systemctl start docker` or `sudo dockerd &`) or use `sandbox: local`",
            service=True,
        ) from None
    return client


def check_image(image: str, client: Any = None) -> None:
    """SandboxError (one line, how to fix it) unless the daemon answers and ``image`` exists."""
    import docker.errors

    client = client or docker_client(10.0)
    try:
        client.images.get(image)
    except docker.errors.ImageNotFound:
        raise SandboxError(f"the sandbox image {image} is missing; build it with `bash scripts/build_sandbox_image.sh`") from None


#: the subject of the commit the SWE-bench harness makes on top of the base commit when it builds an
#: instance image (swebench 4.x ``harness/test_spec/python.py`` ``make_repo_script_list_py``: after
#: the install, ``git commit --allow-empty -am SWE-bench``, so that a diff against HEAD holds only the
#: user's changes; with ``-a`` that commit also holds what the install changed in tracked files)
HARNESS_COMMIT_SUBJECT = "SWE-bench"


def image_commit(run: Callable[[str], CommandResult], base_commit: str, where: str) -> str:
    """The full hash of the commit an image's repository is at (``run`` runs a command in it), which
    the episode's changes are measured against; SandboxError (one line, ``where`` names the
    repository) unless it is ``base_commit`` itself or the SWE-bench harness's layout: one commit
    with the subject :data:`HARNESS_COMMIT_SUBJECT` whose only parent is ``base_commit`` (the
    harness's images: /testbed at the base commit plus that commit, whatever the install changed
    in it). Any other commit - one more or less, another parent, another subject - is refused."""
    res = run("git rev-parse --verify HEAD")
    head = res.output.strip().splitlines()[-1:] if res.exit_code == 0 else []
    if head and head[0].startswith(base_commit):
        return head[0]
    if head:
        top = run("git log -1 --format=%P%n%s HEAD")
        parents, _, subject = top.output.strip().partition("\n") if top.exit_code == 0 else ("", "", "")
        if subject == HARNESS_COMMIT_SUBJECT and len(parents.split()) == 1 and parents.startswith(base_commit):
            return head[0]
    state = f"is at {head[0]}" if head else f"is not a git repository ({res.output.strip()[:120]})"
    raise SandboxError(f"{where} {state}, not at base_commit {base_commit}")


def truncate(data: bytes, cap: int) -> str:
    """The model's view of ``data`` cut to ``cap`` bytes (a multi-byte character cut in two is
    replaced, never an error)."""
    return data[:cap].decode("utf-8", errors="replace")


class DockerSandbox(Sandbox):
    """One container per episode; see the module docstring for what it limits and how."""

    kind: SandboxKind = "docker"

    def __init__(self, spec: SandboxSpec, *, client: Any = None) -> None:
        import docker.errors

        self.spec = spec
        self.workdir = spec.workdir
        self.limits = spec.limits
        self._closed = False
        self._container: Any = None
        # reads must outlast the longest command (the SDK's default read timeout is 60 s)
        self._client = client or docker_client(spec.limits.command_timeout_s + 2 * GUARD_GRACE_S + 60)
        check_image(spec.image, self._client)
        lim = spec.limits
        env = {**BASE_ENV, **spec.env}
        quota = storage_quota_supported(self._client, spec.image)
        #: how the writable places are bounded (:mod:`workers.sandbox.docker_disk`)
        self.disk_bound = "storage-quota" if quota else "read-only+tmpfs"
        home = env.get("HOME", BASE_ENV["HOME"])
        bound: dict[str, Any] = (
            {"storage_opt": {"size": quota_size(lim)}}
            if quota
            else {"read_only": True, "tmpfs": tmpfs_mounts(lim, spec.workdir, home)}
        )
        with tempfile.TemporaryDirectory(prefix="recap-sandbox-clone-") as tmp:
            tar_path: Path | None = None
            if spec.repo_path is not None:  # else the image holds the repository at workdir
                clone = Path(tmp) / "repo"
                self.base_commit = clone_at(spec.repo_path, spec.base_commit, clone)
                tar_path = Path(tmp) / "repo.tar"
                _tar_tree(clone, posixpath.basename(spec.workdir.rstrip("/")), tar_path)
            try:
                self._container = self._client.containers.run(
                    spec.image,
                    ["sleep", "infinity"],
                    detach=True,
                    init=True,
                    labels=dict(spec.labels),
                    environment=env,
                    network_mode="bridge" if lim.network else "none",
                    mem_limit=lim.memory_bytes,
                    memswap_limit=lim.memory_bytes,
                    pids_limit=lim.pids,
                    cap_drop=["ALL"],
                    cap_add=CAPS,
                    security_opt=["no-new-privileges"],
                    working_dir="/",
                    hostname="sandbox",
                    **bound,
                )
                if tar_path is not None:
                    populate(self._client, self._container, spec.workdir, _file_chunks(tar_path))
                elif not quota:  # the tmpfs hides the image's repository: copy it in from the image
                    helper, stream = image_tree(self._client, spec.image, spec.workdir, spec.labels)
                    try:
                        populate(self._client, self._container, spec.workdir, stream)
                    finally:
                        helper.remove(force=True)
            except docker.errors.DockerException as e:
                self.close()
                raise SandboxError(
                    f"starting the sandbox container failed: {str(e).splitlines()[0][:200]}", service=True
                ) from None
            except BaseException:
                self.close()
                raise
        try:
            self._keeper = self._keeper_pid()
        except SandboxError:
            self.close()
            raise
        name, email = GIT_USER
        setup = (
            f"git config --global user.name '{name}' && git config --global user.email '{email}'"
            " && git config --global --add safe.directory '*'"
        )
        res = self.run(setup)
        if res.exit_code != 0:
            self.close()
            raise SandboxError(f"configuring git in the sandbox failed: {res.output.strip()[:200]}")
        if spec.repo_path is None:
            self.base_commit = self._image_commit(spec)

    def _image_commit(self, spec: SandboxSpec) -> str:
        """The commit the image's repository is at, checked by :func:`image_commit` (the sandbox is
        closed when it is refused)."""
        try:
            return image_commit(self.run, spec.base_commit, f"{spec.workdir} in the image {spec.image}")
        except SandboxError:
            self.close()
            raise

    # -- commands -------------------------------------------------------------------------

    @property
    def container_id(self) -> str:
        """The container's id (for logs and the bench)."""
        return str(self._container.id) if self._container is not None else ""

    def _keeper_pid(self) -> str:
        """PID 1's child (``sleep infinity``): the wrapper never kills it. Asked again for a moment
        while the init has not started it yet (just after the container starts): a keeper of "0"
        would let the first command's sweep kill it, and the container with it."""
        for _ in range(100):
            try:
                code, out = self._container.exec_run(["cat", "/proc/1/task/1/children"])
            except Exception as e:  # an API error, or the daemon gone
                self._service_failed(e)
            if code == 0 and out.split():
                return str(out.decode().split()[0])
            time.sleep(0.05)
        return "0"

    def _service_failed(self, exc: Exception) -> NoReturn:
        """Raise the SandboxError (``service``) for a Docker API failure under an open sandbox:
        its container gone, or the daemon erroring."""
        if not self._running():
            raise SandboxError("the sandbox container is gone", service=True) from None
        raise SandboxError(f"the sandbox cannot run commands: {str(exc).splitlines()[0][:200]}", service=True) from None

    def _running(self) -> bool:
        """Whether the container still exists and runs (asked of the daemon)."""
        import docker.errors

        if self._container is None:
            return False
        try:
            self._container.reload()
        except docker.errors.NotFound:
            return False
        except Exception as e:  # the daemon errs or is gone (a refused connection is not a DockerException)
            raise SandboxError(f"the Docker daemon does not answer: {str(e).splitlines()[0][:200]}", service=True) from None
        return bool(self._container.status == "running")

    def _live(self) -> None:
        if self._closed or self._container is None:
            raise SandboxError("the sandbox is closed")

    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        """Run ``command`` with ``bash -c`` in ``workdir`` (see the module docstring)."""
        import docker.errors

        self._live()
        lim = self.limits
        tmo = float(timeout_s if timeout_s is not None else lim.command_timeout_s)
        nonce = secrets.token_hex(8)
        argv = ["bash", "-c", WRAPPER, "wrapper", nonce, f"{tmo:g}", str(lim.output_bytes), str(lim.disk_bytes)]
        argv += [self.workdir, self._keeper, command]
        api = self._client.api
        t0 = time.monotonic()
        try:
            exec_id = api.exec_create(self._container.id, argv, stdout=True, stderr=False)["Id"]
        except docker.errors.NotFound:
            raise SandboxError("the sandbox container is gone", service=True) from None
        except Exception as e:  # an API error, or the daemon gone (requests' ConnectionError)
            self._service_failed(e)
        pool = concurrent.futures.ThreadPoolExecutor(max_workers=1)
        fut = pool.submit(api.exec_start, exec_id, stream=False, demux=False)
        guarded = False
        try:
            raw = fut.result(timeout=tmo + GUARD_GRACE_S)
        except concurrent.futures.TimeoutError:
            guarded = True
            self._unwedge()
            try:
                raw = fut.result(timeout=GUARD_GRACE_S)
            except concurrent.futures.TimeoutError:
                raw = b""
        except Exception as e:  # an API error, or the daemon gone (requests' ConnectionError)
            self._service_failed(e)
        finally:
            pool.shutdown(wait=False)
        duration = time.monotonic() - t0
        parsed = parse(raw or b"", nonce)
        if parsed is None:
            if guarded:
                return CommandResult(None, f"[killed: no answer {tmo:g} s after the timeout]", 0, duration, timed_out=True)
            if not self._running():  # killed under the command (the daemon, an OOM kill, a removal)
                raise SandboxError("the sandbox container is gone", service=True)
            try:
                info = api.exec_inspect(exec_id)
            except Exception as e:  # an API error, or the daemon gone
                self._service_failed(e)
            raise SandboxError(
                f"the sandbox could not run the command wrapper (exit {info.get('ExitCode')}): "
                f"{raw[-200:].decode(errors='replace').strip()}"
            )
        timed_out = guarded or (parsed.rc == 137 and duration >= tmo)
        output = truncate(parsed.output, lim.output_bytes)
        exit_code: int | None = None if (timed_out or parsed.disk_killed) else parsed.rc
        if parsed.repo_bytes > lim.disk_bytes:
            exit_code = None
            output += (
                f"\n[sandbox: the repository folder is {parsed.repo_bytes} bytes, over the "
                f"{lim.disk_bytes}-byte disk limit{'; the command was killed' if parsed.disk_killed else ''}]"
            )
        return CommandResult(
            exit_code,
            output,
            parsed.output_bytes,
            duration,
            timed_out=timed_out,
            truncated=parsed.output_bytes > lim.output_bytes,
        )

    def _unwedge(self) -> None:
        """Kill every process but the init and its keeper; restart the container if even that
        cannot run (no pid left)."""
        script = (
            'for p in /proc/[0-9]*; do p=${p#/proc/}; case " 1 $KEEP $$ " in *" $p "*) continue;; esac; '
            "kill -KILL $p 2>/dev/null; done"
        )
        try:
            code, _ = self._container.exec_run(["bash", "-c", script], environment={"KEEP": self._keeper})
            if code == 0:
                return
        except Exception:
            pass
        try:
            self._container.restart(timeout=0)
            self._keeper = self._keeper_pid()
        except Exception:
            pass

    # -- files --------------------------------------------------------------------------

    def _file_op(self, op: str, path: str, *args: str, data: bytes | None = None) -> tuple[int, bytes]:
        """Run :data:`~workers.sandbox.docker_files.FILE_OP` in the container (resolving ``path``
        there, see :mod:`workers.sandbox.docker_files`); (exit status, stdout)."""
        import docker.errors

        self._live()
        check_path(path)
        argv = ["bash", "-c", FILE_OP, "file-op", op, self.workdir, path, *args]
        try:
            if data is None:
                code, out = self._container.exec_run(argv, stdout=True, stderr=False)
            else:
                code, out = exec_with_stdin(self._client.api, self._container.id, argv, data)
        except docker.errors.NotFound:
            raise SandboxError("the sandbox container is gone", service=True) from None
        except Exception as e:  # an API error, or the daemon gone
            self._service_failed(e)
        if code in (126, 127, -1, None):  # bash or coreutils missing, or the exec never ended
            raise SandboxError(f"the sandbox cannot run its file operations (exit {code}): {bytes(out or b'')[-200:]!r}")
        return int(code), bytes(out or b"")

    def read_file(self, path: str, *, max_bytes: int | None = None) -> bytes:
        """A file's bytes, resolved in the container (:mod:`workers.sandbox.docker_files`);
        :class:`~workers.sandbox.base.FileTooLarge` past ``max_bytes`` (nothing read)."""
        code, out = self._file_op("read", path, str(-1 if max_bytes is None else max_bytes))
        raise_for(code, out, path, max_bytes=max_bytes)
        return parse_read(out, path)

    def read_lines(self, path: str, first: int, last: int | None, max_bytes: int) -> FileSlice:
        """Lines ``first``..``last`` cut to ``max_bytes``, counted and cut in the container: only
        the slice reaches the worker."""
        if first < 1 or (last is not None and last < first) or max_bytes < 0:
            raise ValueError(f"read_lines: bad range {first}..{last} or max_bytes {max_bytes}")
        code, out = self._file_op("lines", path, str(first), str(0 if last is None else last), str(max_bytes))
        raise_for(code, out, path)
        return parse_lines(out, path, max_bytes)

    def write_file(self, path: str, data: bytes) -> None:
        """Create or replace a file at the path resolved in the container (its folders created,
        an existing file's mode kept, a new one 0644), its bytes sent on the exec's stdin."""
        code, out = self._file_op("write", path, data=data)
        raise_for(code, out, path)

    # -- end ----------------------------------------------------------------------------

    def close(self) -> None:
        """Remove the container (forced); safe to call twice."""
        self._closed = True
        c, self._container = self._container, None
        if c is None:
            return
        import docker.errors

        try:
            c.remove(force=True)
        except docker.errors.NotFound:
            pass
        except Exception as e:  # the daemon is gone: the run's next session removes what is left
            log.warning("the sandbox container %s could not be removed: %s", c.id[:12], str(e).splitlines()[0][:200])


def _file_chunks(path: Path, size: int = 1 << 20) -> Iterator[bytes]:
    """``path``'s bytes, ``size`` at a time (a repository's tar is never whole in the worker)."""
    with open(path, "rb") as f:
        while chunk := f.read(size):
            yield chunk


def _tar_tree(src: Path, arcname: str, dest: Path) -> None:
    """Tar ``src`` as ``arcname`` (owned by root inside), symbolic links kept as links."""

    def owner(ti: tarfile.TarInfo) -> tarfile.TarInfo:
        ti.uid = ti.gid = 0
        ti.uname = ti.gname = "root"
        return ti

    with tarfile.open(dest, "w") as tar:
        tar.add(str(src), arcname=arcname, filter=owner)


__all__ = ["DockerSandbox", "docker_client"]
