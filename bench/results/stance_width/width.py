"""Stance width of each policy (stand.yaml, scene seeds 1-3) against its
runtime trials 0-1 at 0.45 and 0.60 m/s, by push direction class.
Run from the repository root after `make`."""
import collections, csv, json, subprocess, tempfile
TMP=tempfile.mkdtemp()
runs={'capture':('capture',None),'r16':('bench/results/swing_cost/r16/r16.safetensors','bench/results/swing_cost/r16/runtime_trials0-1.json'),
'r15':('bench/results/swing_cost/r15/r15.safetensors','bench/results/swing_cost/r15/runtime_trials0-1.json'),
'r19':('bench/results/quiet_cost/r19/r19.safetensors','bench/results/quiet_cost/r19/runtime_trials0-1.json'),
'r20':('bench/results/quiet_cost/r20/r20.safetensors','bench/results/quiet_cost/r20/runtime_trials0-1.json'),
'r11':('bench/results/seeds_base_action/r11/r11.safetensors','bench/results/seeds_base_action/r11/runtime_trials0-1.json'),
'r12':('bench/results/seeds_base_action/r12/r12.safetensors','bench/results/seeds_base_action/r12/runtime_trials0-1.json'),
'r13':('bench/results/seeds_base_action/r13/r13.safetensors','bench/results/seeds_base_action/r13/runtime_trials0-1.json')}
full=json.load(open('bench/results/push_full.json'))
def cls(d):
    d=d%180
    return 'side' if 45<d<135 else ('sag' if d<45 or d>135 else 'diag')
for name,(w,tj) in runs.items():
    a=['--policy','capture'] if w=='capture' else ['--policy','mlp','--weights',w]
    ws=[];ss=[]
    for seed in (1,2,3):
        open(TMP+'/st.yaml','w').write(open('scenarios/stand.yaml').read().replace('seed: 1','seed: %d'%seed))
        subprocess.run(['build/pushstep','--lockstep','--quiet','--scenario',TMP+'/st.yaml','--duration','3.5','--record',TMP+'/w.mcap']+a,stdout=subprocess.DEVNULL,stderr=subprocess.DEVNULL)
        subprocess.run(['build/pushstep','log',TMP+'/w.mcap','--signals','estimate.foot_left_m[0],estimate.foot_left_m[1],estimate.foot_right_m[0],estimate.foot_right_m[1]','--csv',TMP+'/w.csv','--from','2.5','--to','3.4'],stdout=subprocess.DEVNULL,stderr=subprocess.DEVNULL)
        r=list(csv.reader(open(TMP+'/w.csv')))[1:]
        m=lambda i: sum(float(x[i]) for x in r)/len(r)
        ws.append(m(2)-m(4)); ss.append(m(1)-m(3))
    width=sum(ws)/3; stag=sum(ss)/3
    print('   widths', ' '.join('%.3f'%w for w in ws), 'staggers', ' '.join('%+.3f'%w for w in ss))
    if tj: tr=json.load(open(tj))['trials']
    else: tr=[t for t in full['trials'] if t['controller']=='capture' and int(t['id'][-2:])<2]
    ok=collections.Counter(); n=collections.Counter()
    for t in tr:
        if t['dv_m_s'] in (0.45,0.6):
            k=cls(t['direction_deg']); n[k]+=1; ok[k]+= not t['fell']
    tot=sum(not t['fell'] for t in tr)
    print('%-8s width %.3f stagger %+.3f | 0.45+0.60 held: side %2d/%d sag %2d/%d diag %2d/%d | trials0-1 %d' % (name,width,stag,ok['side'],n['side'],ok['sag'],n['sag'],ok['diag'],n['diag'],tot))
