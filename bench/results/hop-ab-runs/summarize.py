#!/usr/bin/env python3
"""Summarises alternating hop runs: nerve-pinned p50 and nerve/raw ratios, old vs new."""
import json, sys, os, re, statistics as st
root = sys.argv[1]
rows = {}
for d in sorted(os.listdir(root)):
    p = os.path.join(root, d, 'hop.json')
    if not os.path.exists(p):
        continue
    j = json.load(open(p))
    txt = open(os.path.join(root, d, 'out.txt')).read()
    load = re.search(r'start \S+ load (\S+)', txt).group(1)
    res = {(r['transport'], r['size']): r for r in j['results']}
    rat = {r['size']: r for r in j['ratios']}
    rows[d] = (load, res, rat)
sizes = [8, 230400, 6220800]
def fmt(x): return '-' if x is None else f'{x:.2f}'
print('| run | load | nerve-pinned p50 µs 8 B / 230 KB / 6.2 MB | futex-pinned 8 B | nerve-pmqos / iox2-waitset-pmqos | nerve / iox2-waitset |')
print('|---|---|---|---|---|---|')
agg = {}
for d, (load, res, rat) in rows.items():
    pin = [res.get(('nerve-pinned', s), {}).get('rtt', {}).get('p50_ns') for s in sizes]
    fp = res.get(('futex-pinned', 8), {}).get('rtt', {}).get('p50_ns')
    pm = [rat.get(s, {}).get('nerve_pmqos_vs_waitset_pmqos_p50') for s in sizes]
    nw = [rat.get(s, {}).get('nerve_vs_waitset_p50') for s in sizes]
    v = d.split('-')[0]
    a = agg.setdefault(v, {'pin': [[], [], []], 'pm': [[], [], []], 'nw': [[], [], []], 'fp': []})
    for i in range(3):
        if pin[i]: a['pin'][i].append(pin[i] / 1000)
        if pm[i]: a['pm'][i].append(pm[i])
        if nw[i]: a['nw'][i].append(nw[i])
    if fp: a['fp'].append(fp / 1000)
    print(f"| {d} | {load} | {' / '.join(fmt(x/1000) if x else '-' for x in pin)} | {fmt(fp/1000 if fp else None)} | {' / '.join(fmt(x) for x in pm)} | {' / '.join(fmt(x) for x in nw)} |")
print()
def ms(xs): return f'{st.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})' if xs else '-'
for v, a in agg.items():
    print(f"{v}: nerve-pinned p50 µs " + ' / '.join(ms(x) for x in a['pin']) + f"; futex-pinned 8 B {ms(a['fp'])}")
    print(f"{v}: nerve-pmqos/iox2-waitset-pmqos " + ' / '.join(ms(x) for x in a['pm']))
    print(f"{v}: nerve/iox2-waitset " + ' / '.join(ms(x) for x in a['nw']))
