"""docker/compose.cluster.yaml brought up with Debian's podman-compose on this machine: the
balancer, three nodes, Redis, PostgreSQL and the queue worker each in its own container, on one
compose network, as a studio runs it (load_tests/failover.py `--kill node-container` and the
tests use it). Users run the same file with Docker Compose (docs/container.md).

What differs from a user's machine, and how:
- No image registry is reachable here. The service image is built from docker/Dockerfile on the
  local bookworm base (deploy/image.py); Redis, PostgreSQL and HAProxy come from local stand-ins of
  the public images (docker/stand-ins: the same programs from Debian bookworm's packages, started
  the same way), named to the compose file through its ${CAMDIRECTOR_*_IMAGE} variables.
- podman runs with runc, cgroupfs and lower process limits than its defaults (deploy/image.py
  says why): a containers.conf of this cluster's folder says so to every podman command that
  podman-compose runs (CONTAINERS_CONF).
- podman's health checks run on systemd timers, absent here, and Debian's podman-compose (1.0.3)
  does not wait for `condition: service_healthy` anyway: `up` starts node-1 alone, runs its
  image's check (`podman healthcheck run`) until it passes, then starts the rest, and waits until
  HAProxy's own checks see every node (its runtime API, through the container's /proc root).
- The host's ports are picked free (${CAMDIRECTOR_GRPC_PORT} and the others), and the TLS folder
  is this cluster's (${CAMDIRECTOR_TLS_DIR}): several runs never collide, and the checkout's
  docker/tls is left alone.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
from functools import cached_property
from pathlib import Path

from camdirector.deploy.haproxy import RuntimeApi
from camdirector.deploy.image import (
    BASE_REVISION,
    build_image,
    container_ulimits,
    local_base,
    podman,
    require_podman,
)
from camdirector.deploy.services import ServiceError, free_port
from camdirector.deploy.tls import make_tls_files

COMPOSE_FILE = Path("docker") / "compose.cluster.yaml"
STAND_INS = {"redis": "CAMDIRECTOR_REDIS_IMAGE", "postgres": "CAMDIRECTOR_POSTGRES_IMAGE", "haproxy": "CAMDIRECTOR_HAPROXY_IMAGE"}
SERVICE_UID = 10001  # docker/Dockerfile's user: it must read the TLS key
DATA_DIR = "/var/lib/camdirector"


def require_podman_compose() -> str:
    path = shutil.which("podman-compose")
    if path is None:
        raise ServiceError("podman-compose is not installed (Debian package podman-compose; scripts/system-deps.sh --tests)")
    return path


def build_stand_ins(root: Path, base: str | None = None, log=print) -> dict[str, str]:
    """docker/stand-ins' three targets built on `base` (default: the local bookworm base);
    {compose variable: image}. Cached by podman after the first build (about a minute)."""
    base = base or local_base(log=log)
    images = {}
    for target, variable in STAND_INS.items():
        tag = f"localhost/camdirector-stand-in-{target}:bookworm-{BASE_REVISION}"
        started = time.monotonic()
        podman(
            "build",
            "--format",
            "docker",
            "--network",
            "host",
            "--build-arg",
            f"BASE={base}",
            "--target",
            target,
            "-t",
            tag,
            str(Path(root) / "docker" / "stand-ins"),
            timeout_s=900,
        )
        log(f"built {tag} in {time.monotonic() - started:.0f} s")
        images[variable] = tag
    return images


def _containers_conf(path: Path) -> Path:
    """podman's settings for every command podman-compose runs (the module docstring)."""
    path.write_text(
        "[containers]\n"
        f"default_ulimits = {json.dumps(container_ulimits())}\n"
        "[engine]\n"
        'runtime = "runc"\n'
        'cgroup_manager = "cgroupfs"\n'
    )
    return path


class ComposeCluster:
    """The compose file's cluster, project `project`, its own files in `folder` (TLS, podman's
    settings, podman-compose's log). `up()` makes one; `down()` removes its containers, network
    and volumes."""

    def __init__(self, root: Path, folder: Path, project: str, env: dict[str, str]):
        self.root, self.folder, self.project, self.env = Path(root), Path(folder), project, dict(env)
        self.file = self.root / COMPOSE_FILE
        # the node services, from the file's service keys (two spaces in): no YAML parser in the installed package
        names = re.findall(r"^  (node-\d+):\s*$", self.file.read_text(), re.MULTILINE)
        self.nodes = sorted(names, key=lambda n: int(n[5:]))
        self.log_path = self.folder / "compose.log"

    @property
    def grpc(self) -> str:
        return f"127.0.0.1:{self.env['CAMDIRECTOR_GRPC_PORT']}"

    @property
    def http(self) -> str:
        return f"127.0.0.1:{self.env['CAMDIRECTOR_HTTP_PORT']}"

    @property
    def ca_file(self) -> Path:
        return self.folder / "tls" / "ca.pem"

    @classmethod
    def up(
        cls,
        root: Path,
        folder: Path,
        *,
        project: str = "camdirector-cluster",
        image: str | None = None,
        stand_ins: bool = True,
        timeout_s: float = 180.0,
        log=print,
    ) -> ComposeCluster:
        """Builds what is missing (the service image, the stand-ins), then brings the cluster up
        and returns once HAProxy sees every node healthy. ServiceError (with the logs' tails) when
        something does not come up within timeout_s."""
        require_podman()
        require_podman_compose()
        root, folder = Path(root).resolve(), Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        tls = make_tls_files(folder / "tls")
        os.chown(tls.key, SERVICE_UID, -1)  # the key stays 0600; the nodes' user reads it
        env = {
            "CAMDIRECTOR_IMAGE": image or build_image(root, log=log),
            "CAMDIRECTOR_TLS_DIR": str(tls.cert.parent),
            "CAMDIRECTOR_GRPC_PORT": str(free_port()),
            "CAMDIRECTOR_HTTP_PORT": str(free_port()),
            "CONTAINERS_CONF": str(_containers_conf(folder / "containers.conf")),
        }
        env.update({f"CAMDIRECTOR_ZMQ_PORT_{k}": str(free_port()) for k in (1, 2, 3)})
        if stand_ins:
            env.update(build_stand_ins(root, log=log))
        cluster = cls(root, folder, project, env)
        cluster.down(keep_folder=True)  # what a killed earlier run of this project left
        (folder / "cluster.json").write_text(json.dumps({"root": str(root), "project": project, "env": env}, indent=1))
        try:
            started = time.monotonic()
            cluster.compose("up", "-d", "--no-build", cluster.nodes[0])
            cluster.wait_healthy(cluster.nodes[0], timeout_s)
            cluster.compose("up", "-d", "--no-build")
            for node in cluster.nodes[1:]:
                cluster.wait_healthy(node, timeout_s - (time.monotonic() - started))
            cluster.wait_balanced(timeout_s=max(10.0, timeout_s - (time.monotonic() - started)))
            log(f"compose cluster {project} up in {time.monotonic() - started:.0f} s")
        except BaseException:
            cluster.down(keep_folder=True)
            raise
        return cluster

    @classmethod
    def attach(cls, folder: Path) -> ComposeCluster:
        """The cluster `up` made with `folder` (its cluster.json), from another process."""
        saved = json.loads((Path(folder) / "cluster.json").read_text())
        return cls(Path(saved["root"]), Path(folder), saved["project"], saved["env"])

    def compose(self, *args: str, timeout_s: float = 300.0) -> None:
        """One podman-compose command on the compose file, its output appended to compose.log."""
        with open(self.log_path, "a") as log:
            log.write(f"\n$ podman-compose {' '.join(args)}\n")
            log.flush()
            done = subprocess.run(
                [require_podman_compose(), "-p", self.project, "-f", str(self.file), *args],
                stdout=log,
                stderr=subprocess.STDOUT,
                env={**os.environ, **self.env},
                timeout=timeout_s,
            )
        if done.returncode != 0:
            raise ServiceError(f"podman-compose {' '.join(args)} exited {done.returncode}: {self._log_tail()}")

    def _log_tail(self, chars: int = 3000) -> str:
        try:
            return self.log_path.read_text()[-chars:]
        except OSError:
            return ""

    def container(self, service: str) -> str:
        """The name of `service`'s container (podman-compose: PROJECT_SERVICE_1)."""
        return f"{self.project}_{service}_1"

    def health(self, service: str) -> bool:
        """`service`'s health check (the compose file's, else its image's) run now: passed?"""
        return podman("healthcheck", "run", self.container(service), check=False).returncode == 0

    def wait_healthy(self, service: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while not self.health(service):
            if time.monotonic() > deadline:
                raise ServiceError(f"{service} is not healthy after {timeout_s:.0f} s: {self.logs(service)}")
            time.sleep(0.5)

    def balancer(self) -> RuntimeApi:
        """HAProxy's runtime API: the container's /tmp/haproxy.sock (compose_config's), reached
        through its main process's root (a short path; rootful podman, so readable here)."""
        pid = json.loads(podman("inspect", self.container("haproxy")).stdout)[0]["State"]["Pid"]
        return RuntimeApi(Path(f"/proc/{pid}/root/tmp/haproxy.sock"))

    def wait_balanced(self, up: list[str] | None = None, timeout_s: float = 30.0) -> float:
        """Waits until HAProxy's checks see the nodes `up` (default all) UP and the others DOWN;
        returns the seconds it took."""
        up = self.nodes if up is None else up
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return self.balancer().wait_until(
                    {n: "UP" if n in up else "DOWN" for n in self.nodes}, timeout_s=max(0.1, deadline - time.monotonic())
                )
            except (OSError, KeyError, IndexError):  # HAProxy starting: no socket yet
                if time.monotonic() > deadline:
                    raise ServiceError(f"haproxy's runtime API did not answer: {self.logs('haproxy')}") from None
                time.sleep(0.25)

    @cached_property
    def admin_key(self) -> str:
        """The admin key node-1 made in the shared volume on its first start."""
        return podman("exec", self.container(self.nodes[0]), "cat", f"{DATA_DIR}/admin.key").stdout.strip()

    def sessions_on(self, node: str) -> set[str]:
        """The ids of the sessions `node` holds, from its own REST listing (asked inside its
        container: the nodes' HTTP ports are reached through the balancer only)."""
        script = (
            "import json, ssl, urllib.request; "
            f"key = open('{DATA_DIR}/admin.key').read().strip(); "
            "r = urllib.request.Request('https://127.0.0.1:8080/v1/sessions', headers={'Authorization': 'Bearer ' + key}); "
            "print(urllib.request.urlopen(r, context=ssl._create_unverified_context(), timeout=10).read().decode())"
        )
        listing = json.loads(podman("exec", self.container(node), "python", "-c", script).stdout)
        return {s["session_id"] for s in listing["sessions"]}

    def kill(self, service: str) -> None:
        """SIGKILL to every process of `service`'s container (as a crash or a power cut). podman,
        as Docker, counts `kill` as the user's stop: the restart policy leaves it down until
        `start`."""
        podman("kill", self.container(service))
        podman("wait", self.container(service), timeout_s=60, check=False)

    def start(self, service: str) -> None:
        """`service`'s container started again (after `kill`), on the same volumes."""
        podman("start", self.container(service))

    def logs(self, service: str, chars: int = 3000) -> str:
        done = podman("logs", self.container(service), check=False)
        return (done.stdout + done.stderr)[-chars:]

    def down(self, keep_folder: bool = False) -> None:
        """Containers, network and volumes removed; the folder too unless `keep_folder`. podman
        directly, all at once: `podman-compose down` stops them one by one, a second apart."""
        names = podman(
            "ps", "-a", "--filter", f"label=com.docker.compose.project={self.project}", "--format", "{{.Names}}", check=False
        ).stdout.split()
        if names:
            podman("rm", "-f", "-t", "0", *names, check=False)
        for volume in ("camdirector-data", "postgres-data"):
            podman("volume", "rm", "-f", f"{self.project}_{volume}", check=False)
        podman("network", "rm", "-f", f"{self.project}_default", check=False)
        if not keep_folder:
            shutil.rmtree(self.folder, ignore_errors=True)
