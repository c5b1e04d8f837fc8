"""The service image (docker/Dockerfile) built and run with Debian's podman, on a machine that
reaches no image registry: what tests/deploy/test_image.py runs, and scripts/podman-image.sh for
people. Everything needs a checkout (the Dockerfile and the sources it copies): `root` is its top.

podman runs as root here with runc and cgroupfs (crun fails on these machines' cgroups) and with
the host's network for builds and containers (no bridge, no port publishing; the servers in the
container bind loopback ports picked free on the host, so they never collide with another run).

The Dockerfile's `FROM` comes from the BASE build argument: users keep the public
python:3.11-slim-bookworm; here `local_base()` makes a Debian bookworm root file system with
debootstrap (from the mirror apt already uses), with Debian's python3 and python3-venv in it, and
imports it into podman once: later calls find it by its tag. It trusts what this host trusts (the
host's extra CA certificates are added), so pip reaches PyPI through the same proxy the host does.

Nothing is installed here (scripts/system-deps.sh --tests installs podman, runc and debootstrap);
a missing program is a `ServiceError` (deploy/services.py) that says which package provides it.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from camdirector.deploy.services import ServiceError

RUNC = "/usr/sbin/runc"
PODMAN = ["--runtime", RUNC, "--cgroup-manager", "cgroupfs"]
# The local base's recipe: change BASE_REVISION with it so that machines holding an older base make a new one.
BASE_REVISION = "1"
LOCAL_BASE = f"localhost/camdirector-base:bookworm-{BASE_REVISION}"
BASE_PACKAGES = ("python3", "python3-venv", "ca-certificates")
PUBLIC_BASE = "python:3.11-slim-bookworm"
IMAGE = "localhost/camdirector"
VERSION_LABEL = "org.opencontainers.image.version"


def require_podman() -> str:
    """podman's path; ServiceError where podman or runc is missing."""
    path = shutil.which("podman")
    if path is None:
        raise ServiceError("podman is not installed (Debian packages podman and runc; scripts/system-deps.sh --tests)")
    if not Path(RUNC).exists():
        raise ServiceError(f"{RUNC} is missing (Debian package runc; scripts/system-deps.sh --tests)")
    return path


def podman(*args: str, timeout_s: float = 120.0, check: bool = True, **kwargs) -> subprocess.CompletedProcess:
    """One podman command with this machine's runtime flags; its output, as text."""
    done = subprocess.run([require_podman(), *PODMAN, *args], capture_output=True, text=True, timeout=timeout_s, **kwargs)
    if check and done.returncode != 0:
        raise ServiceError(f"podman {' '.join(args[:3])} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return done


def image_exists(name: str) -> bool:
    return podman("image", "exists", name, check=False).returncode == 0


def apt_mirror() -> str:
    """The Debian mirror apt uses on this host (its sources), else deb.debian.org."""
    for source in [
        *Path("/etc/apt/sources.list.d").glob("*.sources"),
        Path("/etc/apt/sources.list"),
        *Path("/etc/apt/sources.list.d").glob("*.list"),
    ]:
        try:
            text = source.read_text()
        except OSError:
            continue
        for line in text.splitlines():
            words = line.split()
            if words[:1] == ["URIs:"] and len(words) > 1 and not words[1].rstrip("/").endswith("-security"):
                return words[1]
            if words[:1] == ["deb"]:
                url = next((w for w in words[1:] if "://" in w), "")
                if url and not url.rstrip("/").endswith("-security"):
                    return url
    return "http://deb.debian.org/debian"


def local_base(name: str = LOCAL_BASE, log=print) -> str:
    """A bookworm base with Debian's python3 in podman under `name`, made once (debootstrap, about
    a minute or two); later calls only find it."""
    if image_exists(name):
        return name
    debootstrap = shutil.which("debootstrap") or (Path("/usr/sbin/debootstrap").exists() and "/usr/sbin/debootstrap")
    if not debootstrap:
        raise ServiceError("debootstrap is not installed (Debian package debootstrap; scripts/system-deps.sh --tests)")
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="camdirector-base-") as work:
        rootfs = Path(work) / "rootfs"
        done = subprocess.run(
            [debootstrap, "--variant=minbase", f"--include={','.join(BASE_PACKAGES)}", "bookworm", str(rootfs), apt_mirror()],
            capture_output=True,
            text=True,
            timeout=1200,
        )
        if done.returncode != 0:
            raise ServiceError(f"debootstrap exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
        # the host's extra CAs (a TLS-inspecting proxy's, a studio's own): pip in the build trusts them as the host does
        extra = sorted(Path("/usr/local/share/ca-certificates").glob("*.crt"))
        if extra:
            for cert in extra:
                shutil.copy(cert, rootfs / "usr/local/share/ca-certificates" / cert.name)
            subprocess.run(["chroot", str(rootfs), "update-ca-certificates"], check=True, capture_output=True, timeout=120)
        for leftover in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for item in (rootfs / leftover).glob("*"):
                if item.is_file():
                    item.unlink()
        tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        archive = tar.stdout
        assert archive is not None  # stdout=PIPE
        try:
            podman(
                "import",
                "--change",
                'CMD ["/bin/bash"]',
                "--change",
                "ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt",
                "--change",
                f"LABEL camdirector.base-revision={BASE_REVISION}",
                "-",
                name,
                stdin=archive,
                timeout_s=600,
            )
        finally:
            archive.close()
            tar.wait()
    log(f"made {name} in {time.monotonic() - started:.0f} s")
    return name


def version_of(root: Path) -> str:
    """The project's version, as the checkout's pyproject.toml says."""
    import tomllib

    return tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]


def build_image(root: Path, base: str | None = None, tag: str | None = None, log=print) -> str:
    """docker/Dockerfile built from the checkout at `root` on `base` (default: the local base,
    made if missing), tagged IMAGE:VERSION; returns the tag. podman's layer cache makes a rebuild
    of unchanged sources take seconds; a change under src/ reruns only the project's install."""
    root = Path(root).resolve()
    version = version_of(root)
    tag = tag or f"{IMAGE}:{version}"
    base = base or local_base(log=log)
    started = time.monotonic()
    # --format docker: the OCI format has no HEALTHCHECK. The build's output goes to a log file
    # (a pipe could fill); its tail is in the error when it fails.
    with tempfile.TemporaryFile("w+") as output:
        done = subprocess.run(
            [
                require_podman(),
                *PODMAN,
                "build",
                "--format",
                "docker",
                "--network",
                "host",
                "--build-arg",
                f"BASE={base}",
                "--build-arg",
                f"VERSION={version}",
                "-f",
                str(root / "docker" / "Dockerfile"),
                "-t",
                tag,
                str(root),
            ],
            stdout=output,
            stderr=subprocess.STDOUT,
            timeout=1800,
        )
        if done.returncode != 0:
            output.seek(0)
            raise ServiceError(f"podman build exited {done.returncode}:\n{output.read()[-6000:]}")
    log(f"built {tag} in {time.monotonic() - started:.0f} s")
    return tag


def inspect(name: str, kind: str = "image") -> dict:
    return json.loads(podman(kind, "inspect", name).stdout)[0]


def image_label(tag: str, label: str = VERSION_LABEL) -> str | None:
    return (inspect(tag).get("Labels") or {}).get(label)


def image_size(tag: str) -> int:
    """The image's size in bytes, all layers (base included)."""
    return int(inspect(tag)["Size"])


def container_ulimits() -> list[str]:
    """The --ulimit values a container gets here. podman's defaults for open files and processes
    (1048576) are above what these machines allow (runc then fails: "error setting rlimit type 7"):
    this process's open files, and 32768 processes at most (the process limit the host reports is
    refused too)."""
    nofile = resource.getrlimit(resource.RLIMIT_NOFILE)
    nproc = [min(limit, 32768) if limit >= 0 else 32768 for limit in resource.getrlimit(resource.RLIMIT_NPROC)]
    return [f"nofile={nofile[0]}:{nofile[1]}", f"nproc={nproc[0]}:{nproc[1]}"]


class Container:
    """One container of the image on the host's network, `name` unique on this machine; its
    data directory the named volume `volume`. start() / kill() / start() again keep the volume."""

    def __init__(
        self,
        image: str,
        name: str,
        volume: str,
        args: Sequence[str] = (),
        env: dict[str, str] | None = None,
        mounts: Sequence[str] = (),
    ):
        self.image, self.name, self.volume = image, name, volume
        self.args, self.env, self.mounts = list(args), dict(env or {}), list(mounts)
        self.created = False

    def start(self) -> Container:
        """Creates and starts it the first time, starts it again after a kill."""
        if not self.created:
            # --health-interval disable: no timer (podman's are systemd's, absent here);
            # `podman healthcheck run` (health()) still runs the image's check.
            run = [
                "run",
                "-d",
                "--name",
                self.name,
                "--network",
                "host",
                *(arg for limit in container_ulimits() for arg in ("--ulimit", limit)),
                "--health-interval",
                "disable",
                "-v",
                f"{self.volume}:/var/lib/camdirector",
            ]
            for mount in self.mounts:
                run += ["-v", mount]
            for key, value in self.env.items():
                run += ["-e", f"{key}={value}"]
            podman(*run, self.image, *self.args)
            self.created = True
        else:
            podman("start", self.name)
        return self

    def kill(self) -> None:
        """SIGKILL to every process in it (`podman kill`): no shutdown, as a crash or a power cut."""
        podman("kill", self.name)
        podman("wait", self.name, timeout_s=60, check=False)

    def running(self) -> bool:
        return inspect(self.name, "container")["State"]["Running"]

    def health(self) -> str:
        """The image's HEALTHCHECK run now: "healthy" or "unhealthy"."""
        done = podman("healthcheck", "run", self.name, check=False)
        return "healthy" if done.returncode == 0 else f"unhealthy: {done.stdout.strip()} {done.stderr.strip()}"

    def exec(self, *command: str) -> str:
        return podman("exec", self.name, *command).stdout

    def logs(self, chars: int = 4000) -> str:
        done = podman("logs", self.name, check=False)
        return (done.stdout + done.stderr)[-chars:]

    def volume_path(self) -> Path:
        """Where the volume's files are on the host (rootful podman: readable by root)."""
        return Path(inspect(self.volume, "volume")["Mountpoint"])

    def remove(self) -> None:
        """The container and its volume, gone."""
        podman("rm", "-f", "-t", "0", self.name, check=False)
        podman("volume", "rm", "-f", self.volume, check=False)


def save_image(tag: str, path: Path) -> Path:
    """`tag` saved as a docker archive at `path` (what `docker load -i` and `podman load -i` read;
    uncompressed: gzip it where its size matters more than a minute)."""
    podman("save", "--format", "docker-archive", "-o", str(path), tag, timeout_s=900)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="podman-image.sh", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("base", help=f"make the local bookworm base ({LOCAL_BASE}) if missing")
    build = sub.add_parser("build", help="build docker/Dockerfile as IMAGE:VERSION (on the local base by default)")
    build.add_argument("--root", type=Path, default=Path.cwd(), help="the checkout (default: here)")
    build.add_argument("--base", help=f"the base image (default: the local base; users: {PUBLIC_BASE})")
    build.add_argument("--tag")
    save = sub.add_parser("save", help="save an image as a docker archive (docker load -i / podman load -i)")
    save.add_argument("tag")
    save.add_argument("file", type=Path)
    args = parser.parse_args(argv)

    def log(line: str) -> None:  # progress on stderr: stdout is the answer, one line of JSON
        print(line, file=sys.stderr)

    try:
        if args.command == "base":
            print(local_base(log=log))
        elif args.command == "save":
            print(
                json.dumps(
                    {"image": args.tag, "file": str(save_image(args.tag, args.file)), "size_bytes": args.file.stat().st_size}
                )
            )
        else:
            tag = build_image(args.root, args.base, args.tag, log=log)
            print(json.dumps({"image": tag, "version": image_label(tag), "size_bytes": image_size(tag)}))
    except ServiceError as exc:
        print(f"podman-image: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
