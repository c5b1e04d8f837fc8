"""The `camdirector` command."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from camdirector.access.cli import add_parsers as add_key_parsers
from camdirector.bridges.cast_cli import add_parser as add_cast_parser
from camdirector.evaluation.cli import add_parsers as add_eval_parsers
from camdirector.matches.import_cli import add_parser as add_import_match_parser
from camdirector.matches.play_cli import add_parser as add_play_match_parser
from camdirector.precompute.overview.cli import add_parsers as add_overview_parsers
from camdirector.precompute.tracks.cli import add_parsers as add_track_parsers
from camdirector.server_settings import FRAME_PATHS, FRONTS, ServerSettings
from camdirector.version import PROTOCOL, VERSION


def _serve_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("serve", help="run the director service")
    p.add_argument("--grpc", dest="grpc_addr", help="gRPC HOST:PORT ('' turns it off; port 0 picks one)")
    p.add_argument("--zmq", dest="zmq_addr", help="ZeroMQ tcp://HOST:PORT ('' turns it off; port * picks one)")
    p.add_argument("--http", dest="http_addr", help="HTTP HOST:PORT for /healthz, /metrics, REST ('' turns it off)")
    p.add_argument(
        "--live",
        dest="live_addr",
        help="HOST:PORT of the liveness port a balancer checks (plain HTTP GET /live; '' the default: none)",
    )
    p.add_argument("--workers", type=int, help="worker processes (0: sessions in the front process)")
    p.add_argument("--max-sessions", dest="max_sessions", type=int)
    p.add_argument(
        "--map-threads",
        dest="map_threads",
        type=int,
        help="threads one ANTICIPATION map update shares (0: the cores with --workers 0, else 1)",
    )
    p.add_argument("--max-objects", dest="max_objects", type=int)
    p.add_argument("--max-triangles", dest="max_triangles", type=int)
    p.add_argument("--max-message-bytes", dest="max_message_bytes", type=int)
    p.add_argument(
        "--session-resume-s",
        dest="session_resume_s",
        type=float,
        help="seconds an idle session without a stream is kept for a client to resume",
    )
    p.add_argument("--data-dir", dest="data_dir", help="recordings and artifacts")
    p.add_argument("--record-all", dest="record_all", action="store_const", const=True, help="record every session")
    p.add_argument("--max-concurrent-jobs", dest="max_concurrent_jobs", type=int)
    p.add_argument("--max-queued-jobs", dest="max_queued_jobs", type=int)
    p.add_argument("--max-upload-bytes", dest="max_upload_bytes", type=int)
    p.add_argument("--max-json-body-bytes", dest="max_json_body_bytes", type=int, help="largest JSON body of an HTTP route")
    p.add_argument(
        "--job-retention-s",
        dest="job_retention_s",
        type=float,
        help="seconds a finished offline job's result is kept (0: forever)",
    )
    p.add_argument(
        "--job-store",
        dest="job_store",
        help="job records: empty for SQLite in the data directory, or postgresql://USER@HOST:PORT/DB",
    )
    p.add_argument(
        "--job-queue",
        dest="job_queue",
        help="empty to run jobs in this process's runner, or redis://HOST:PORT/DB for the shared queue",
    )
    p.add_argument(
        "--checkpoint-store",
        dest="checkpoint_store",
        help="session checkpoints: empty for a folder in the data directory, redis://HOST:PORT/DB "
        "to let any node restore any session, or off",
    )
    p.add_argument(
        "--checkpoint-every-frames",
        dest="checkpoint_every_frames",
        type=int,
        help="frames between two snapshots of a session's state",
    )
    p.add_argument(
        "--checkpoint-wait-ms",
        dest="checkpoint_wait_ms",
        type=float,
        help="how long a frame waits for its checkpoint write before it goes on without it (docs/protocol.md)",
    )
    p.add_argument("--node-id", dest="node_id", help="this node's name (default: host name and pid)")
    p.add_argument(
        "--no-auth",
        dest="auth",
        action="store_const",
        const=False,
        help="let every caller in without a key (a machine of your own; docs/security.md)",
    )
    p.add_argument("--tls-cert", dest="tls_cert", help="PEM certificate chain: serve gRPC and HTTP over TLS")
    p.add_argument("--tls-key", dest="tls_key", help="the certificate's PEM private key")
    p.add_argument(
        "--insecure",
        dest="insecure",
        action="store_const",
        const=True,
        help="allow plaintext on a non-loopback address (TLS ends at a proxy you trust)",
    )
    p.add_argument(
        "--tenant-max-sessions", dest="tenant_max_sessions", type=int, help="sessions one tenant may have open on this node"
    )
    p.add_argument("--tenant-max-fps", dest="tenant_max_fps", type=float, help="frames a second into one session")
    p.add_argument(
        "--tenant-max-upload-bytes",
        dest="tenant_max_upload_bytes",
        type=int,
        help="bytes of uploads one tenant's jobs may hold at once",
    )
    p.add_argument(
        "--tenant-max-queued-jobs",
        dest="tenant_max_queued_jobs",
        type=int,
        help="jobs one tenant may have queued or running at once",
    )
    p.add_argument(
        "--tenant-max-live-views",
        dest="tenant_max_live_views",
        type=int,
        help="live monitor streams one tenant may hold open on this node",
    )
    p.add_argument(
        "--pose-output-allow",
        dest="pose_output_allow",
        action="append",
        metavar="CIDR",
        help="an IPv4 network sessions' pose outputs may send to (default: 127.0.0.0/8 only); repeatable",
    )
    p.add_argument(
        "--frame-path",
        dest="frame_path",
        choices=FRAME_PATHS,
        help="where sessions' per-frame work runs: compiled (the default; so far the TORIC rig's frames in every "
        "visibility mode, TRACKS and MATCH in Python; docs/frame_path.md) or python (the reference)",
    )
    p.add_argument(
        "--grpc-front",
        dest="grpc_front",
        choices=FRONTS,
        help="what serves the gRPC port: compiled (the default: the edge in Rust, a session's frames straight "
        "to its worker) or python (grpc.aio alone; docs/frame_path.md)",
    )
    p.add_argument(
        "--zmq-front",
        dest="zmq_front",
        choices=FRONTS,
        help="what reads the ZeroMQ socket: compiled (the default: the same edge, a session's Frame requests "
        "straight to its worker) or python (docs/frame_path.md)",
    )
    p.add_argument(
        "--plugin",
        dest="plugins",
        action="append",
        metavar="MODULE",
        help="a Python module to import at start, in the front and every worker (a studio's own match "
        "director registers itself); repeatable",
    )


def _job_worker_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("job-worker", help="run offline jobs from the shared job queue (jobs/queue.py)")
    p.add_argument("--job-queue", dest="job_queue", help="the queue, redis://HOST:PORT/DB (required)")
    p.add_argument(
        "--job-store",
        dest="job_store",
        help="job records: empty for SQLite in the data directory, or postgresql://USER@HOST:PORT/DB",
    )
    p.add_argument("--data-dir", dest="data_dir", help="the data directory every node mounts (uploads, results, levels)")
    p.add_argument("--concurrency", type=int, help="jobs run at once by this worker (default: --max-concurrent-jobs's)")
    p.add_argument(
        "--heartbeat-timeout-s",
        dest="heartbeat_timeout_s",
        type=float,
        help="a worker silent this long is taken for dead and its jobs run again (same on every worker)",
    )
    p.set_defaults(handler=_job_worker)


def _job_worker(args: argparse.Namespace) -> int:
    import dataclasses

    from camdirector.jobs import JobSettings, run_job_worker

    try:
        settings = ServerSettings.from_env(data_dir=args.data_dir, job_store=args.job_store, job_queue=args.job_queue)
        if not settings.job_queue:
            raise ValueError("--job-queue redis://HOST:PORT/DB is required")
        jobs = dataclasses.replace(
            JobSettings.for_server(settings),
            **{
                k: v
                for k, v in (("max_concurrent_jobs", args.concurrency), ("worker_heartbeat_timeout_s", args.heartbeat_timeout_s))
                if v is not None
            },
        )
    except ValueError as exc:
        print(f"camdirector job-worker: {exc}", file=sys.stderr)
        return 2
    return run_job_worker(settings.data_dir, jobs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="camdirector", description="Automated cinematographer service")
    parser.add_argument("--version", action="version", version=f"camdirector {VERSION} (protocol {PROTOCOL})")
    sub = parser.add_subparsers(dest="command", required=True)
    _serve_parser(sub)
    _job_worker_parser(sub)
    add_eval_parsers(sub)
    add_overview_parsers(sub)
    add_track_parsers(sub)
    add_key_parsers(sub)
    add_play_match_parser(sub)
    add_import_match_parser(sub)
    add_cast_parser(sub)
    p = sub.add_parser("replay", help="replay a session recording and check the poses bit for bit")
    p.add_argument("file", type=Path)
    p.add_argument(
        "--data-dir",
        dest="data_dir",
        type=Path,
        help="where a TRACKS session's level is registered (default: the folder the recording is in)",
    )
    p.add_argument(
        "--frame-path",
        dest="frame_path",
        choices=FRAME_PATHS,
        default=ServerSettings.frame_path,
        help=f"the frame path of the server that made the recording (default: {ServerSettings.frame_path}, "
        "the server's default): a recording replays bit for bit only on the path that made it",
    )
    p = sub.add_parser("demo", help="server plus demo client on a built-in scene; writes a video")
    p.add_argument("--out", type=Path, default=Path("out"))
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--transport", choices=("grpc", "zmq"), default="grpc")
    p.add_argument(
        "--visibility", default="ANTICIPATION", choices=("ANTICIPATION", "NO_ANTICIPATION", "RAYCAST", "REACTIVE", "FRAMING_ONLY")
    )
    args = parser.parse_args(argv)

    if args.command == "serve":
        overrides = {k: v for k, v in vars(args).items() if k != "command"}
        overrides["plugins"] = tuple(args.plugins) if args.plugins else None
        overrides["pose_output_allow"] = tuple(args.pose_output_allow) if args.pose_output_allow else None
        try:
            settings = ServerSettings.from_env(**overrides)
        except ValueError as exc:
            parser.error(str(exc))
        from camdirector.front.main import run

        return run(settings)
    if args.command == "replay":
        from camdirector.worker.replay import replay

        try:
            report = replay(args.file, data_dir=args.data_dir, frame_path=args.frame_path)
        except (OSError, ValueError) as exc:
            print(f"camdirector replay: {exc}", file=sys.stderr)
            return 2
        print(json.dumps(report.as_dict()))
        return 0 if report.ok else 1
    if args.command == "demo":
        from camdirector.demo.client import run_demo

        return run_demo(out_dir=args.out, seconds=args.seconds, transport=args.transport, visibility=args.visibility)
    return args.handler(args)  # eval, overview, eval-overview, level, eval-graph, keys


if __name__ == "__main__":
    sys.exit(main())
