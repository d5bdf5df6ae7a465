#!/usr/bin/env bash
# Checks that the runtime image's package list (docker/Dockerfile, stage "runtime") covers every
# shared library the objdb binaries load directly: each NEEDED entry of `readelf -d` is resolved
# to its file (ldconfig's cache), the file to its Debian package (`dpkg -S`), and the package must
# be installed by the runtime stage's apt-get line or be part of every Debian base image (the
# Essential and Priority-required packages and their dependencies, such as libc6 and zlib1g). Runs without Docker, on the
# build machine, which must be the image's Debian release. Exit 0: covered; 1: what is missing.
# Usage: [DOCKERFILE=F] scripts/check_runtime_libs.sh [BINARY...]
#        (default docker/Dockerfile; build/bin/objdb-server build/bin/objdb)
set -euo pipefail
cd "$(dirname "$0")/.."

dockerfile=${DOCKERFILE:-docker/Dockerfile}
binaries=("$@")
[[ ${#binaries[@]} -gt 0 ]] || binaries=(build/bin/objdb-server build/bin/objdb)
for b in "${binaries[@]}"; do
  [[ -x $b ]] || { echo "check_runtime_libs: no binary $b (build first: scripts/build.sh)" >&2; exit 2; }
done
for tool in readelf dpkg ldconfig python3; do
  command -v "$tool" >/dev/null || { echo "check_runtime_libs: needs $tool" >&2; exit 2; }
done

# The runtime stage's packages: the words of its `apt-get install` command (continued lines).
image_packages=$(awk '
  /^FROM .* AS runtime/ { runtime = 1; next }
  /^FROM / { runtime = 0 }
  runtime && /apt-get install/ { install = 1 }
  install {
    line = $0; sub(/#.*/, "", line); n = split(line, words, /[ \t\\]+/)
    for (i = 1; i <= n; i++) if (words[i] ~ /^[a-z0-9][a-z0-9.+-]+$/ && words[i] != "apt-get" &&
                                 words[i] != "install" && words[i] != "rm" && words[i] != "update")
      print words[i]
    if (line !~ /\\[ \t]*$/ || line ~ /&&/ && line !~ /install/) install = 0
  }' "$dockerfile" | sort -u)
[[ -n $image_packages ]] || { echo "check_runtime_libs: no apt-get install in the runtime stage of $dockerfile" >&2; exit 2; }

# What every Debian base image holds (debian:bookworm-slim included): the Essential and the
# Priority-required packages with everything they depend on, from this machine's dpkg database.
base_packages=$(python3 - <<'PY'
import re
packages, deps = {}, {}
for stanza in open("/var/lib/dpkg/status").read().split("\n\n"):
    fields = dict(re.findall(r"^([A-Za-z-]+): ?(.*)$", stanza, re.M))
    name = fields.get("Package")
    if not name or "installed" not in fields.get("Status", ""):
        continue
    packages[name] = fields.get("Essential") == "yes" or fields.get("Priority") == "required"
    wanted = ",".join(fields.get(k, "") for k in ("Depends", "Pre-Depends"))
    deps[name] = [re.split(r"[\s:(]", alt.strip())[0] for d in wanted.split(",") if d.strip()
                  for alt in d.split("|")]
todo = [p for p, root in packages.items() if root]
seen = set(todo)
while todo:
    for d in deps.get(todo.pop(), []):
        if d in packages and d not in seen:
            seen.add(d)
            todo.append(d)
print("\n".join(sorted(seen)))
PY
)
cache=$(ldconfig -p)
missing=0
checked=0
declare -A seen=()
for b in "${binaries[@]}"; do
  while read -r soname; do
    [[ -n $soname && -z ${seen[$soname]:-} ]] || continue
    seen[$soname]=1
    checked=$((checked + 1))
    path=$(awk -v so="$soname" '$1 == so && /x86-64/ { print $NF; exit }' <<<"$cache")
    [[ -n $path ]] || path=$(awk -v so="$soname" '$1 == so { print $NF; exit }' <<<"$cache")
    if [[ -z $path ]]; then
      echo "MISSING $soname (needed by $b): not in ldconfig's cache"
      missing=$((missing + 1))
      continue
    fi
    real=$(readlink -f "$path")
    package=$(dpkg -S "$path" 2>/dev/null || dpkg -S "$real" 2>/dev/null || true)
    package=${package%%:*}
    if [[ -z $package ]]; then
      echo "MISSING $soname ($path, needed by $b): no Debian package owns it"
      missing=$((missing + 1))
      continue
    fi
    if grep -qx "$package" <<<"$image_packages"; then
      echo "ok      $soname  $package"
      continue
    fi
    if grep -qx "$package" <<<"$base_packages"; then
      echo "ok      $soname  $package (in every Debian base image)"
      continue
    fi
    echo "MISSING $soname  $package (needed by $b): add it to the runtime stage of $dockerfile"
    missing=$((missing + 1))
  done < <(readelf -d "$b" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
done
if ((missing > 0)); then
  echo "check_runtime_libs: $missing of $checked libraries are not covered by $dockerfile's runtime packages"
  exit 1
fi
echo "check_runtime_libs: all $checked libraries ${binaries[*]} load are covered by $dockerfile's runtime packages"
