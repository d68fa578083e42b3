import json,struct,hashlib,sys,os
def tensors(p):
    b=open(p,'rb').read(); n=struct.unpack('<Q',b[:8])[0]; h=json.loads(b[8:8+n]); data=b[8+n:]
    meta=h.pop('__metadata__',{})
    return {k:hashlib.sha256(data[v['data_offsets'][0]:v['data_offsets'][1]]).hexdigest() for k,v in h.items()}, meta
out={}
for t in sys.argv[1:]:
    r={}
    for f in ['teacher/model.safetensors','student/model.safetensors']:
        a,ma=tensors(f'before_{t}/{f}'); b,mb=tensors(f'after_{t}/{f}')
        r[f]={'tensors':len(a),'identical_tensor_data':a==b,'metadata_keys_differing':sorted(k for k in set(ma)|set(mb) if ma.get(k)!=mb.get(k))}
    ob=open(f'before_{t}/model.onnx','rb').read(); oa=open(f'after_{t}/model.onnx','rb').read()
    r['model.onnx']={'bytes_identical':ob==oa,'bytes':len(oa)}
    for sp in ['val','novel','voice']:
        mb=json.load(open(f'before_{t}/eval/{sp}/metrics.json'))['models']; ma=json.load(open(f'after_{t}/eval/{sp}/metrics.json'))['models']
        r[f'metrics_{sp}']={'same_scores':[{k:v for k,v in m.items() if 'time' not in k and 's_per' not in k and k!='ms'} for m in mb]==[{k:v for k,v in m.items() if 'time' not in k and 's_per' not in k and k!='ms'} for m in ma]}
    out[t]=r
print(json.dumps(out,indent=1))
