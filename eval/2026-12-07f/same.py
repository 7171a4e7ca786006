import json,sys
a={ (x['benchmark'],x['pair']):x for x in map(json.loads,open(sys.argv[1]))}
b=[json.loads(l) for l in open(sys.argv[2])]
diff=[x for x in b if a[(x['benchmark'],x['pair'])]['t_target_source']!=x['t_target_source']]
dv=[x for x in b if a[(x['benchmark'],x['pair'])]['confident']!=x['confident']]
print('compared',len(b),'poses differ',len(diff),'verdict differs',len(dv))
