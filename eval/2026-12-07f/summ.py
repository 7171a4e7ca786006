"""RR, RE, TE, median and summed seconds per benchmark present in each records file, and the
verdict's confusion over the file: python3 summ.py RECORDS.jsonl ..."""
import json, statistics as st, sys

for f in sys.argv[1:]:
    r = [json.loads(l) for l in open(f)]
    print(f)
    for b in ['3DMatch', '3DLoMatch']:
        x = [y for y in r if y['benchmark'] == b]
        if not x:
            continue
        reg = [y for y in x if y['registered']]
        print('  %s RR %.1f RE %.3f TE %.4f med %.3f sum %.0f' % (
            b, 100 * len(reg) / len(x), st.mean(y['re_deg'] for y in reg),
            st.mean(y['te'] for y in reg), st.median(y['seconds'] for y in x),
            sum(y['seconds'] for y in x)))
    fail = [y for y in r if not y['registered']]
    reg = [y for y in r if y['registered']]
    fc = sum(y['confident'] for y in fail)
    rd = sum(not y['confident'] for y in reg)
    print('  failed+confident %d/%d (%.2f%%) registered+doubted %d/%d (%.2f%%)' % (
        fc, len(fail), 100 * fc / max(len(fail), 1), rd, len(reg), 100 * rd / max(len(reg), 1)))
