#!/usr/bin/env python3
"""Sorts the ThreadSanitizer reports of scripts/tsan.sh and exits 1 if any is left for us.

Only our code is instrumented; Debian's gRPC, protobuf, abseil, GDAL and libgomp are not, so TSan
cannot see the synchronisation inside them and reports races that are not there. Each access of a
data race is attributed to the innermost frame past the sanitizer and the C++ standard headers:
ours (this tree, generated protobuf code included unless only gRPC runs it), gRPC's (its
libraries, abseil, protobuf, grpcpp headers) or another library's. Counted, not shown:
  third-party - neither access is ours (a lock-order cycle: no lock of it taken by our code);
  openmp      - an access inside a PCL OpenMP region (`_omp_fn`, or on a thread libgomp made):
                libgomp's barrier is invisible;
  grpc        - ours against gRPC's (a message or buffer handed over through gRPC), or two of
                ours both under gRPC's callbacks where one creates or destroys the object (a
                constructor, destructor, new or delete before the first frame of ours, or the
                lost stack of the gRPC thread that allocated it: a reactor made by a handler,
                then called back on another thread): gRPC's completion-queue handoff is
                invisible.
Everything else is printed whole: races between our accesses (frames in the C++, Eigen, PCL and
Boost headers count as their caller's), lock-order cycles through our locks, and every other kind of report that has a frame of
ours (mutex misuse, use after free, leaked threads).
usage: tsan_triage.py ROOT LOG"""
import collections
import os
import re
import sys

ACCESS = re.compile(
    r"\n  ((?:Previous )?(?:[Aa]tomic )?(?:[Ww]rite|[Rr]ead) of size.*?)(?=\n\n|$)", re.S)
ACQUIRE = re.compile(r"\n  (Mutex \S+ acquired here.*?)(?=\n\n|$)", re.S)
FRAME = re.compile(r"#\d+ (.+?) (\S+) \((\S+?)\+")
CREATING = re.compile(r"(?:\S+::)?(\w+)::~?\1\(|operator new|operator delete|^free$|^malloc$|"
                      r"ObjectDatabaseService::Ingest\(")


def frames(block):
    return [(m.group(1), m.group(2), m.group(3)) for m in FRAME.finditer(block)]


GRPC = re.compile(r"libgrpc|libgpr|libabsl|libprotobuf|libupb|libaddress_sorting|"
                  r"/usr/include/grpcpp/|/usr/include/grpc/|/usr/include/google/protobuf/|"
                  r"/usr/include/absl/")


# Header-only code compiled into our binaries (instrumented): the caller decides.
HEADER_ONLY = re.compile(r"/usr/include/(c\+\+/|x86_64-linux-gnu/c\+\+/|eigen3/|pcl-[\d.]+/|boost/)")


def owner(block, root):
    """'ours', 'grpc' or 'other' for the innermost frame past the sanitizer and std headers."""
    for _, path, module in frames(block):
        if "libsanitizer" in path or HEADER_ONLY.match(path):
            continue
        if path.startswith(root):
            # Generated protobuf code run by gRPC alone (parsing, serialising, destroying a
            # message it owns) is gRPC's handling of the message.
            if "/proto/gen/" in path and not any(
                    p.startswith(root) and "/proto/gen/" not in p for _, p, _ in frames(block)):
                return "grpc"
            return "ours"
        return "grpc" if GRPC.search(path) or GRPC.search(module) else "other"
    return "other"


def created_by(access, report, library):
    """The access ran on a thread that `library` created (its stack may not be restorable)."""
    thread = re.search(r"by thread (T\d+)", access)
    if not thread:
        return False
    created = re.search(r"\n  Thread " + thread.group(1) + r" .*? created by .*?(?=\n\n|$)",
                        report, re.S)
    return bool(created) and library in created.group(0)


def on_openmp_thread(access, report):
    return created_by(access, report, "libgomp")


def lost_on_grpc_thread(access, report):
    """An access whose stack TSan lost, on the gRPC thread that allocated the location (a handler
    creating its reactor)."""
    thread = re.search(r"by thread (T\d+)", access)
    return ("[failed to restore the stack]" in access and bool(thread) and
            thread.group(1) == allocated_by(report) and
            created_by(access, report, "grpc_core::Thread"))


def creates_or_destroys(block, root):
    """A constructor, destructor, new, delete or the Ingest handler among the innermost frames,
    up to and including the first frame of ours."""
    for function, path, _ in frames(block):
        if CREATING.search(function):
            return True
        if path.startswith(root):
            return False
    return False


def allocated_by(report):
    m = re.search(r"\n  Location is heap block .*? allocated by (?:thread (T\d+)|main thread)", report)
    return (m.group(1) or "main") if m else None


def under_grpc(block):
    return "grpc::internal::" in block or "libgrpc" in block


def kind(report, root):
    title = report.split("\n", 1)[0]
    if "lock-order-inversion" in title:
        taken = ACQUIRE.findall(report)
        return "ours" if any(owner(b, root) == "ours" for b in taken) else "third-party"
    if "data race" not in title:
        return "ours" if any(p.startswith(root) for _, p, _ in frames(report)) else "third-party"
    accesses = ACCESS.findall(report)[:2]
    if len(accesses) < 2:
        return "ours"  # not understood: shown
    owners = [owner(a, root) for a in accesses]
    if "ours" not in owners:
        return "third-party"
    if any("_omp_fn" in a or on_openmp_thread(a, report) for a in accesses):
        return "openmp"
    if "grpc" in owners:
        return "grpc"
    if len(accesses) == 2 and all(under_grpc(a) or lost_on_grpc_thread(a, report) for a in accesses):
        if any(creates_or_destroys(a, root) or lost_on_grpc_thread(a, report) for a in accesses):
            return "grpc"
    return "ours"


def main():
    root = os.path.realpath(sys.argv[1]).rstrip("/") + "/"
    log = open(sys.argv[2], errors="replace").read()
    reports = [r.split("SUMMARY:")[0] for r in log.split("WARNING: ThreadSanitizer:")[1:]]
    kinds = collections.Counter()
    left = []
    for report in reports:
        k = kind(report, root)
        if k == "ours":
            left.append(report)
        else:
            kinds[k] += 1
    excused = "".join(f"{n} {k}, " for k, n in sorted(kinds.items()))
    print(f"tsan_triage: {len(reports)} reports: {excused}{len(left)} ours")
    for report in left:
        print("WARNING: ThreadSanitizer:" + report)
    return 1 if left else 0


if __name__ == "__main__":
    sys.exit(main())
