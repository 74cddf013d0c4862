"""The container a SWE-bench Verified episode runs in: the harness's image, or the ReCAP release's.

The paper's two SWE-bench numbers came from two set-ups (README, "SWE-bench: which set-up made
which number"), and the option ``container`` chooses between them per sweep or, by default, per
method (:func:`default_container`):

* ``harness``: the SWE-bench harness's per-instance image, the repository at ``/testbed`` with its
  environment installed (:mod:`.images`, :mod:`.env`). mini-SWE-agent's 39.58 % is the leaderboard
  run ``20250726_mini-v1.0.0_gpt-4.1-2025-04-14``, which ran there.
* ``release``: where the authors' ``swebench-recap/`` ran ReCAP (44.8 %). Their
  ``run_swe_bench_tasks.py:82-93`` gives SWE-agent only ``--env.repo.github_url`` (the instance's
  ``https://github.com/<repo>``, ``:14-15,73``) and ``--env.repo.base_commit``; ``config/recap.yaml``
  sets no ``env`` section, so the environment is SWE-agent's default: the ``python:3.11`` image
  (``sweagent/environment/swe_env.py:27-30``) with the network on (a Docker default nothing turns
  off), the repository fetched at the base commit alone (a depth-1 fetch of that commit and a
  checkout of it, ``sweagent/environment/repo.py:159-182``) into ``/<owner>__<name>``
  (``repo.py:143-146``, the working folder: ``swe_env.py:155-157``), nothing installed (no
  ``post_startup_commands``, ``swe_env.py:35``), and the variables ``swe_env.py:189`` and
  ``config/recap.yaml:109-115`` set. The diff the agent leaves is then graded in the harness's
  image, as the release's predictions file was (``collect_predictions.py``): here too.

What ``release`` does here: the image is ``release_image`` (default :data:`RELEASE_IMAGE`, a
local image: nothing is pulled); the repository is fetched on this host the way ``repo.py:168-173``
fetches it (``git init``, ``git fetch --depth 1 <source> <base_commit>``, a detached checkout),
from GitHub or, offline, from ``repo_mirror`` (a folder holding ``<owner>__<name>`` git
repositories), then copied in as every sandbox's repository is (:mod:`workers.sandbox.repo_copy`:
one commit of history, no remote left; the release keeps its ``origin`` remote). The episode's
sandbox keeps its limits (command time, output cap) and its labels; the evaluation opens the
harness's image as ``harness`` does.
"""

from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from recap.env import Reset
from workers.sandbox.base import Sandbox, SandboxError, SandboxSpec

from .env import VerifiedEnvironment

Container = Literal["harness", "release"]
CONTAINERS: tuple[Container, ...] = ("harness", "release")
#: what ``make()`` uses when neither the sweep nor the method says (the harness's image)
DEFAULT_CONTAINER: Container = "harness"
#: SWE-agent's default deployment image (swebench-recap/sweagent/environment/swe_env.py:28)
RELEASE_IMAGE = "python:3.11"
#: where the release fetches the repository from (run_swe_bench_tasks.py:14-15)
GITHUB = "https://github.com/{repo}"
#: seconds the fetch may take (swebench-recap/sweagent/environment/repo.py:131, ``clone_timeout``)
FETCH_TIMEOUT_S = 500.0
#: the variables the release's shell has: swe_env.py:189, then the tools' config/recap.yaml:109-115
RELEASE_ENV: Mapping[str, str] = {
    "LANG": "C.UTF-8",
    "LC_ALL": "C.UTF-8",
    "PIP_PROGRESS_BAR": "off",
    "PAGER": "cat",
    "MANPAGER": "cat",
    "LESS": "-R",
    "TQDM_DISABLE": "1",
    "GIT_PAGER": "cat",
}
#: the limits of SWE-agent's tool execution that swebench-recap ran ReCAP under (its
#: ``ToolConfig`` defaults; ``config/recap.yaml`` sets none): 30 s per command
#: (sweagent/tools/tools.py:139), 1800 s of commands in all (:145), the episode ended after 3
#: commands in a row that timed out (:150). ReCAP's released settings (one tool call per reply,
#: workers/envs/swe/benchmark.py RELEASED_RECAP) bring them unless the sweep sets its own
RELEASE_TOOL_LIMITS: Mapping[str, Any] = {"command_timeout_s": 30.0, "wall_time_s": 1800.0, "max_timeouts_in_row": 3}
#: the options this module reads (the benchmark accepts them)
OPTIONS = ("container", "release_image", "repo_mirror")
#: each method's container when the sweep sets none: the set-up its paper number came from
METHOD_CONTAINERS: Mapping[str, Container] = {"recap": "release", "mini_swe": "harness"}


def default_container(style: str) -> Container:
    """The container an agent ``style`` runs in unless the sweep says: ReCAP the release's (its
    44.8 %), mini-SWE-agent the harness's (its 39.58 %), any other the harness's."""
    return METHOD_CONTAINERS.get(style, DEFAULT_CONTAINER)


def agent_options(style: str, config: Any = None) -> dict[str, Any]:
    """The ``make()`` options of a method's set-up unless the sweep sets them: its container and,
    for mini-SWE-agent with 1.0.0's configuration (``profile: released``), the network on, as 1.0.0
    started the harness's image (``docker run`` with no network option:
    ``microsweagent/environments/docker.py:41-53``)."""
    out: dict[str, Any] = {"container": default_container(style)}
    if style == "mini_swe" and getattr(config, "package_config", None) == "1.0.0":
        out["network"] = True
    if style == "recap" and getattr(config, "tool_calls_per_reply", None) == "one":
        out.update(RELEASE_TOOL_LIMITS)  # ReCAP as swebench-recap ran it (profile: released)
    return out


@dataclass(frozen=True)
class ReleaseContainer:
    """The ``release`` container of one sweep entry: its image and where repositories come from
    (``mirror`` None: GitHub)."""

    image: str = RELEASE_IMAGE
    mirror: str | None = None
    fetch_timeout_s: float = FETCH_TIMEOUT_S

    def workdir(self, repo: str) -> str:
        """``/<owner>__<name>``: where the release's repository sits (repo.py:143-146)."""
        owner, _, name = repo.partition("/")
        return f"/{owner}__{name}"

    def source(self, repo: str) -> str:
        """The repository to fetch from: ``<mirror>/<owner>__<name>``, or GitHub's URL."""
        if self.mirror is None:
            return GITHUB.format(repo=repo)
        return str(Path(self.mirror) / self.workdir(repo).lstrip("/"))

    def check_source(self, repo: str) -> None:
        """ValueError (one line) when the mirror lacks ``repo`` (GitHub is not checked: no request
        is made before an episode)."""
        if self.mirror is None:
            return
        path = Path(self.source(repo))
        if not (path / ".git").exists() and not (path / "HEAD").is_file():
            raise ValueError(f"repo_mirror {self.mirror} has no git repository {path.name} for {repo}")


def container_of(options: Mapping[str, Any]) -> Container:
    """``options["container"]`` checked (ValueError, one line, for a bad value)."""
    value = options.get("container", DEFAULT_CONTAINER)
    if value not in CONTAINERS:
        raise ValueError(f"container must be one of {', '.join(CONTAINERS)}, got {value!r}")
    return value


def release_of(options: Mapping[str, Any]) -> ReleaseContainer | None:
    """The ``release`` container ``options`` ask for (None: ``harness``); ValueError (one line) for
    a bad ``container``, ``release_image`` or ``repo_mirror`` (the last two are checked whichever
    container runs: a method's default may make it ``release``)."""
    container = container_of(options)
    image = options.get("release_image", RELEASE_IMAGE)
    if not isinstance(image, str) or not image.strip() or any(c.isspace() for c in image):
        raise ValueError(f"release_image must be a Docker image name, got {image!r}")
    mirror = options.get("repo_mirror")
    if mirror is not None:
        if not isinstance(mirror, str) or not mirror.strip():
            raise ValueError(f"repo_mirror must be a folder path, got {mirror!r}")
        if not Path(mirror).expanduser().is_dir():
            raise ValueError(f"repo_mirror {mirror} is not a folder (it holds one <owner>__<name> git repository per repo)")
        mirror = str(Path(mirror).expanduser().resolve())
    if container != "release":
        return None
    return ReleaseContainer(image=image, mirror=mirror)


def missing_image(release: ReleaseContainer, present: set[str]) -> str | None:
    """The one line preflight refuses with when the release's image is not among ``present``."""
    names = {release.image, f"{release.image}:latest"} if ":" not in release.image.rpartition("/")[2] else {release.image}
    if names & present:
        return None
    return (
        f"container release runs in the image {release.image}, which is not here; `docker pull {release.image}` "
        "where a registry is reachable, or set release_image to a local image"
    )


def fetch_at(source: str, base_commit: str, dest: Path, timeout_s: float = FETCH_TIMEOUT_S, *, remote: bool = True) -> None:
    """``dest`` a repository holding ``base_commit`` alone, checked out (detached): what the
    release's clone leaves (repo.py:168-173), fetched on this host; SandboxError (one line) when
    the source or the commit cannot be reached: a service failure (``infra_error``, run again on
    resume) for a ``remote`` source (GitHub: the network may come back), the instance's own for a
    local mirror (it would fail the same way again)."""
    dest.mkdir(parents=True)
    for args in (
        ["init", "--quiet"],
        ["fetch", "--quiet", "--depth", "1", source, base_commit],
        ["checkout", "--quiet", "--detach", "FETCH_HEAD"],
    ):
        try:
            proc = subprocess.run(["git", *args], cwd=dest, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise SandboxError(f"fetching {base_commit} from {source} took over {timeout_s:g} s", service=remote) from None
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or [""])[-1][:200]
            raise SandboxError(
                f"git {args[0]} of {base_commit} from {source} failed: {last}", service=remote and args[0] == "fetch"
            )


OpenSandbox = Callable[[SandboxSpec], Sandbox]


def release_opener(open_sandbox: OpenSandbox, release: ReleaseContainer, repo: str) -> OpenSandbox:
    """``open_sandbox`` for the episode: the repository fetched at the spec's base commit into a
    temporary folder, handed over as the spec's ``repo_path`` (the sandbox copies it in as it
    opens), the folder removed once it is open."""

    def open_release(spec: SandboxSpec) -> Sandbox:
        with tempfile.TemporaryDirectory(prefix="recap-release-repo-") as tmp:
            dest = Path(tmp) / "repo"
            fetch_at(release.source(repo), spec.base_commit, dest, release.fetch_timeout_s, remote=release.mirror is None)
            return open_sandbox(replace(spec, repo_path=str(dest)))

    return open_release


class ReleaseEnvironment(VerifiedEnvironment):
    """A SWE-bench Verified instance played in the release's container (see the module
    docstring), its diff graded in the harness's image (``self.spec`` stays the harness's: the
    evaluation opens it)."""

    def __init__(self, *args: Any, release: ReleaseContainer, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.release = release
        self.container: Container = "release"
        repo = self.instance.repo
        self.episode_spec = replace(
            self.spec, repo_path=None, image=release.image, workdir=release.workdir(repo), env=dict(RELEASE_ENV)
        )
        self._open_episode = release_opener(self._open, release, repo)

    @property
    def workdir(self) -> str:
        """The repository folder as commands see it: ``/<owner>__<name>``."""
        if self._sandbox is not None:
            return self._sandbox.workdir
        return self._last_workdir or self.episode_spec.workdir

    def reset(self) -> Reset:
        """The release's container at the base commit (the evaluation's spec and opener are put
        back as soon as it is open)."""
        spec, opener = self.spec, self._open
        self.spec, self._open = self.episode_spec, self._open_episode
        try:
            return super().reset()
        finally:
            self.spec, self._open = spec, opener
