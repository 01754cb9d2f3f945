"""A fleet's archive on Dask: one log per task, then the health history.

    python dask_archive.py ARCHIVE [ARCHIVE ...] --rows rows.jsonl [--workers N]
    python dask_archive.py ARCHIVE --address tcp://scheduler:8786 --rows rows.jsonl

Logs are files, directories searched recursively for .tlog, .bin and .ulg (in any case,
sorted by path) and glob patterns, found as `ahcmon scan` finds them. Each log is replayed by `ahcmon.replay` in a Dask
task; the rows come back in the logs' order, the same rows `ahcmon scan` writes. Without
--address the bag runs on local processes (`--workers`, default one per core); with it, on
the dask.distributed cluster there (needs the `distributed` package, and `ahcmon` installed
on its workers). A log that cannot be read is named with its reason and the others go on
(exit 1, as scan; exit 2 when no log is found). --profile and --airframes are scan's. The history of the rows (`ahcmon.history`) is printed: one line per
airframe x actuator, and its alarm.
"""

import argparse
import glob
import json
import os
import sys

import dask.bag as db

import ahcmon

EXTENSIONS = {".tlog", ".bin", ".ulg"}


def walk(directory, found, unreadable):
    """A directory's logs as `ahcmon scan` orders them: each level's entries sorted by path,
    subdirectories in place (links to directories not followed), paths joined as given."""
    try:
        entries = sorted(os.path.join(directory, e) for e in os.listdir(directory))
    except OSError as e:
        unreadable.append(f"{directory}: {e.strerror or e}")
        return
    for entry in entries:
        if os.path.isdir(entry) and not os.path.islink(entry):
            walk(entry, found, unreadable)
        elif os.path.splitext(entry)[1].lower() in EXTENSIONS:
            found.append(entry)


def find_logs(paths):
    """As `ahcmon scan`: files as named, directories searched, glob patterns expanded; each
    file once. Returns the logs, the directories that could not be read, the paths that name
    nothing."""
    found, unreadable, nothing = [], [], []
    for p in paths:
        if os.path.isdir(p):
            walk(p, found, unreadable)
        elif os.path.lexists(p):
            found.append(p)
        elif any(c in p for c in "*?["):
            matches = sorted(glob.glob(p, recursive=True))
            if not matches:
                nothing.append(p)
            for m in matches:
                if os.path.isdir(m):
                    walk(m, found, unreadable)
                else:
                    found.append(m)
        else:
            nothing.append(p)
    logs, seen = [], set()
    for f in found:
        key = os.path.realpath(f)
        if key not in seen:
            seen.add(key)
            logs.append(f)
    return logs, unreadable, nothing


def replay_one(path, profile=None, airframes=None):
    """One task: (path, rows, None), or (path, [], why) for a log that cannot be read."""
    try:
        return path, ahcmon.replay(path, profile=profile, airframes=airframes), None
    except (OSError, ValueError) as e:
        return path, [], str(e)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+", help="logs or directories of logs")
    ap.add_argument("--rows", required=True, help="write the rows here (JSON lines)")
    ap.add_argument("--workers", type=int, default=None, help="local processes")
    ap.add_argument("--address", help="a dask.distributed scheduler's address")
    ap.add_argument("--profile", help="as scan's --profile: a built-in name or a TOML file")
    ap.add_argument("--airframes", help="as scan's --airframes: a TOML file")
    args = ap.parse_args()

    logs, unreadable, nothing = find_logs(args.paths)
    for why in unreadable:
        print(why, file=sys.stderr)
    for p in nothing:
        print(f"{p}: no such file or directory", file=sys.stderr)
    if not logs:
        print(f"no log in {', '.join(args.paths)}", file=sys.stderr)
        sys.exit(2)
    bag = db.from_sequence(logs, npartitions=len(logs)).map(
        replay_one, profile=args.profile, airframes=args.airframes
    )
    if args.address:
        from dask.distributed import Client

        with Client(args.address):
            results = bag.compute()
    else:
        results = bag.compute(scheduler="processes", num_workers=args.workers)

    rows, failed = [], []
    for path, log_rows, why in results:
        if why is not None:
            failed.append((path, why))
        rows.extend(log_rows)
    with open(args.rows, "w") as f:
        for row in rows:
            f.write(json.dumps(row, separators=(",", ":")) + "\n")
    for _, why in failed:
        print(why, file=sys.stderr)

    for s in ahcmon.history(rows):
        alarm = s["alarm_from_flight"]
        print(
            f"{s['airframe']:<12} {s['actuator']:<9} {len(s['flights']):>3} flights"
            + (f"  ALARM from flight {alarm}" if alarm else "")
        )
    failed_total = len(failed) + len(unreadable)
    print(
        f"{len(logs)} logs, {len(rows)} rows, {failed_total} could not be read, "
        f"{len(nothing)} paths named nothing"
    )
    sys.exit(1 if failed_total or nothing else 0)


if __name__ == "__main__":
    main()
