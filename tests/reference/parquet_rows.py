"""Read `ahcmon scan --parquet`'s table with pyarrow and pandas and compare it, value by value,
with the same scan's JSON lines flattened (`mit_ukf.gamma` -> `mit_ukf_gamma`).

usage: parquet_rows.py ROWS.jsonl TABLE.parquet
Prints "ok <rows> rows <columns> columns" and the schema's (name, type, nullable) as JSON."""
import json
import math
import sys

import pandas as pd
import pyarrow.parquet as pq

rows_path, table_path = sys.argv[1], sys.argv[2]
rows = []
with open(rows_path) as f:
    for line in f:
        row = json.loads(line)
        flat = {}
        for k, v in row.items():
            if isinstance(v, dict):
                for kk, vv in v.items():
                    flat[f"{k}_{kk}"] = vv
            else:
                flat[k] = v
        rows.append(flat)

table = pq.read_table(table_path)
df = pd.read_parquet(table_path)
assert len(df) == len(rows) == table.num_rows, (len(df), len(rows), table.num_rows)
columns = list(df.columns)
keys = set().union(*(r.keys() for r in rows)) if rows else set()
missing = keys - set(columns)
assert not missing, f"keys of the rows not in the table: {sorted(missing)}"
for i, (row, rec) in enumerate(zip(rows, table.to_pylist())):
    for c in columns:
        want, got = row.get(c), rec[c]
        if want is None:
            assert got is None, f"row {i} {c}: {got!r}, want null"
        elif isinstance(want, float) or isinstance(got, float):
            assert got is not None and math.isclose(got, want, rel_tol=0, abs_tol=0), (
                f"row {i} {c}: {got!r} != {want!r}"
            )
        else:
            assert got == want, f"row {i} {c}: {got!r} != {want!r}"
schema = [(f.name, str(f.type), f.nullable) for f in table.schema]
print(f"ok {len(rows)} rows {len(columns)} columns")
print(json.dumps(schema))
