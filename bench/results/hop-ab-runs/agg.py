import sys, re, collections
# perf script output: samples separated by blank lines; first line header with event, then frames
ev_counts = collections.Counter(); keys = collections.defaultdict(collections.Counter)
skip = re.compile(r'pthread_mutex_lock|Mutex<T>::lock|MutexProtected|^malloc|__GI___libc_malloc|alloc::alloc|__rust_alloc|__rdl_alloc|RawVec|raw_vec|alloc::|<alloc|core::ptr|Vec<T|String|to_owned|to_string|ToString|ToOwned|clone')
sample = []
def flush():
    if not sample: return
    hdr = sample[0]; m = re.search(r'probe_libc:(\w+)', hdr)
    if not m: return
    ev = m.group(1); ev_counts[ev] += 1
    frames = [re.sub(r'^\s*[0-9a-f]+\s+', '', f).rsplit(' (', 1)[0] for f in sample[1:]]
    first = next((f for f in frames if not skip.search(f)), '?')
    sdk = next((f for f in frames if 'agent_sdk' in f and 'task_main' not in f), '-')
    keys[ev][(first[:110], sdk[:90])] += 1
for line in sys.stdin:
    if line.strip() == '':
        flush(); sample = []
    else:
        sample.append(line.rstrip('\n'))
flush()
for ev, c in keys.items():
    tot = ev_counts[ev]
    print(f'== {ev}: {tot} samples')
    for (first, sdk), n in c.most_common(14):
        print(f'{100*n/tot:5.1f}%  {first}   <- {sdk}')
