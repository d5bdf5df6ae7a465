#!/usr/bin/env python3
"""Checks what docker/compose*.yaml and docker/Dockerfile refer to, without Docker: build
contexts and Dockerfiles exist, every image is built by one service only (a service that runs an
image another builds neither builds nor pulls it), depends_on names services, named volumes are
declared, the Dockerfile's COPY sources exist, its build stage installs the build packages only
(scripts/deps.sh --build-only, which deps.sh must know), and its HEALTHCHECK has a start period.

    scripts/check_compose.py [COMPOSE_FILE...] [--dockerfile FILE]

Prints each problem as "FILE: problem" and exits 1 if there is any; 0 and "ok" otherwise.
"""

import argparse
import re
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent


def check_compose(path: Path, problems: list) -> None:
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        problems.append(f"{path}: cannot be read: {e}")
        return
    services = doc.get("services") or {}
    declared_volumes = set((doc.get("volumes") or {}).keys())
    builders = {}  # image -> services that build it
    for name, service in services.items():
        build = service.get("build")
        image = service.get("image")
        if build is not None:
            if isinstance(build, str):
                build = {"context": build}
            context = (path.parent / build.get("context", ".")).resolve()
            if not context.is_dir():
                problems.append(f"{path}: service {name}: build context {context} does not exist")
            dockerfile = context / build.get("dockerfile", "Dockerfile")
            if not dockerfile.is_file():
                problems.append(f"{path}: service {name}: Dockerfile {dockerfile} does not exist")
            if image:
                builders.setdefault(image, []).append(name)
        for dependency in (service.get("depends_on") or {}):
            if dependency not in services:
                problems.append(f"{path}: service {name} depends on {dependency}, no such service")
        for volume in service.get("volumes") or []:
            source = volume.split(":")[0] if isinstance(volume, str) else volume.get("source", "")
            named = source and not source.startswith((".", "/", "~"))
            if named and source not in declared_volumes:
                problems.append(f"{path}: service {name} uses volume {source}, not declared")
    for image, names in builders.items():
        if len(names) > 1:
            problems.append(f"{path}: image {image} is built {len(names)} times "
                            f"({', '.join(names)}): build it once")
    for name, service in services.items():
        image = service.get("image")
        if service.get("build") is None and image in builders and \
                service.get("pull_policy") != "never":
            problems.append(f"{path}: service {name} runs {image}, which {builders[image][0]} "
                            "builds, without pull_policy: never (compose would try to pull it)")


def check_dockerfile(path: Path, problems: list) -> None:
    text = path.read_text()
    context = ROOT  # docker build -f docker/Dockerfile . from the repository root
    for line in text.splitlines():
        m = re.match(r"\s*COPY\s+(?!--from)(.+)", line)
        if not m:
            continue
        sources = m.group(1).split()[:-1]
        for source in sources:
            if source.startswith("--"):
                continue
            if source != "." and not (context / source).exists():
                problems.append(f"{path}: COPY source {source} does not exist")
    if "scripts/deps.sh --build-only" not in text:
        problems.append(f"{path}: the build stage should run scripts/deps.sh --build-only "
                        "(the build packages, not the test ones)")
    if "--build-only" not in (ROOT / "scripts" / "deps.sh").read_text():
        problems.append("scripts/deps.sh does not know --build-only")
    health = re.search(r"HEALTHCHECK[^\n]*", text)
    if not health or "--start-period" not in health.group(0):
        problems.append(f"{path}: HEALTHCHECK without --start-period: a large database takes "
                        "minutes to open, which is starting, not unhealthy")


def main(argv) -> int:
    parser = argparse.ArgumentParser(description="The compose files' references are sound.")
    parser.add_argument("composes", nargs="*", type=Path)
    parser.add_argument("--dockerfile", type=Path, default=ROOT / "docker" / "Dockerfile")
    args = parser.parse_args(argv)
    dockerfile = args.dockerfile
    composes = args.composes or sorted((ROOT / "docker").glob("compose*.yaml"))
    problems = []
    for c in composes:
        check_compose(c, problems)
    check_dockerfile(dockerfile, problems)
    for p in problems:
        print(p)
    if problems:
        return 1
    print(f"ok: {len(composes)} compose files and {dockerfile}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
