#!/usr/bin/python3
"""Compares two baked binary glTFs of one scene whose meshes differ in their vertices (a
Draco-compressed file and its plain twin: Draco reorders, welds and drops degenerate
triangles, so vertex-by-vertex comparison does not apply): per mesh primitive (by node and
primitive index), the area-weighted mean of _IRRADIANCE's green channel over its triangles;
prints how far the second file's means are from the first's (median, 90th percentile,
worst, the area-weighted relative RMS) and the ratio of the area-weighted totals.

usage: area-means.py PLAIN.glb OTHER.glb   (bake ... -o X.glb writes them)
"""
import json, struct, sys
import numpy as np
C={5120:np.int8,5121:np.uint8,5122:np.int16,5123:np.uint16,5125:np.uint32,5126:np.float32}
W={"SCALAR":1,"VEC2":2,"VEC3":3,"VEC4":4}
def load(path):
    d=open(path,'rb').read(); jl=struct.unpack_from('<I',d,12)[0]; j=json.loads(d[20:20+jl])
    at=20+jl; bl=struct.unpack_from('<I',d,at)[0]; b=d[at+8:at+8+bl]
    def acc(i):
        a=j['accessors'][i]; v=j['bufferViews'][a['bufferView']]; dt=np.dtype(C[a['componentType']]); w=W[a['type']]
        off=v.get('byteOffset',0)+a.get('byteOffset',0); st=v.get('byteStride',dt.itemsize*w)
        raw=np.frombuffer(b,np.uint8,count=st*(a['count']-1)+dt.itemsize*w,offset=off)
        return np.lib.stride_tricks.as_strided(raw.view(np.uint8),shape=(a['count'],dt.itemsize*w),strides=(st,1)).copy().view(dt).reshape(a['count'],w)
    out={}
    for ni,n in enumerate(j['nodes']):
        if 'mesh' not in n: continue
        for pi,p in enumerate(j['meshes'][n['mesh']]['primitives']):
            P=acc(p['attributes']['POSITION']).astype(np.float64); E=acc(p['attributes']['_IRRADIANCE']).astype(np.float64)
            I=acc(p['indices']).reshape(-1,3).astype(np.int64)
            a=0.5*np.linalg.norm(np.cross(P[I[:,1]]-P[I[:,0]],P[I[:,2]]-P[I[:,0]]),axis=1)
            e=E[I].mean(axis=1)[:,1]
            out[(ni,pi)]=(float((a*e).sum()/max(a.sum(),1e-30)), float(a.sum()))
    return out
A=load(sys.argv[1]); B=load(sys.argv[2])
errs=[]; num=den=0
for k,(ea,aa) in A.items():
    eb,ab=B[k]; errs.append(abs(eb-ea)/max(ea,1e-9)); num+=eb*aa; den+=ea*aa
errs=np.array(errs)
print("primitives %d; area-weighted mean irradiance per primitive, draco against plain: median %.2f%%, p90 %.2f%%, max %.2f%%; area-weighted total ratio %.4f" % (len(errs), 100*np.median(errs), 100*np.percentile(errs,90), 100*errs.max(), num/den))
worst=sorted(A.keys(), key=lambda k: -abs(B[k][0]-A[k][0])/max(A[k][0],1e-9))[:6]
tot=sum(a for _,a in A.values())
for k in worst: print(k, "plain %.4g draco %.4g area share %.2e" % (A[k][0], B[k][0], A[k][1]/tot))
num=sum(a*(B[k][0]-e)**2 for k,(e,a) in A.items()); den=sum(a*e*e for k,(e,a) in A.items())
print("area-weighted relative RMS of the per-primitive means: %.2f%%" % (100*(num/den)**0.5))
