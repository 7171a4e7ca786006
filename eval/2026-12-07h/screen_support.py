import sys,collections
for f in sys.argv[1:]:
    rows=[tuple(map(int,(l.split()[2],l.split()[4],l.split()[6]))) for l in open(f) if l.startswith("SCRH")]
    n=len(rows)
    print(f, n, "hypotheses")
    for P in [1,2,3,4,5,6]:
        skip=[r for r in rows if r[1]<P]
        lost=[r for r in skip if r[2]>=8]
        lost15=[r for r in skip if r[2]>=15]
        print(f"  pre<{P}: skip {len(skip)} ({100*len(skip)/n:.0f}%), of them post>=8: {len(lost)}, post>=15: {len(lost15)}; max post {max([r[2] for r in skip] or [0])}")
