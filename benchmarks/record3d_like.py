"""A Record3D-style "EXR + JPG" export made from the RealSense sequence of ../shared/data, for timing
`holo video --recording` where no phone export is at hand (docs/BENCHMARKS.md, "Phone recordings at the
output size"): frames 10-17, colour upscaled to 1920 x 1440 JPEG, depth subsampled to 256 x 192 OpenEXR
metres (uncompressed, one scanline per block), metadata.json with a nominal camera matrix and no poses.

Usage: python benchmarks/record3d_like.py OUT_DIR [SHARED_DATA_DIR]   (default ../shared/data)
"""
import json
import os
import struct
import sys

import numpy as np
from PIL import Image

D = os.path.join(sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"), "realsense_seq")
out = sys.argv[1]
os.makedirs(out + "/rgb", exist_ok=True)
os.makedirs(out + "/depth", exist_ok=True)
def attr(name,typ,data): return name.encode()+b'\0'+typ.encode()+b'\0'+struct.pack('<i',len(data))+data
def write_exr(path, a):
    h,w=a.shape
    ch=b'Y\0'+struct.pack('<iB3xii',2,0,1,1)+b'\0'
    hdr=b'\x76\x2f\x31\x01'+struct.pack('<i',2)
    hdr+=attr('channels','chlist',ch)+attr('compression','compression',b'\0')
    box=struct.pack('<iiii',0,0,w-1,h-1)
    hdr+=attr('dataWindow','box2i',box)+attr('displayWindow','box2i',box)
    hdr+=attr('lineOrder','lineOrder',b'\0')+attr('pixelAspectRatio','float',struct.pack('<f',1.0))
    hdr+=attr('screenWindowCenter','v2f',struct.pack('<ff',0,0))+attr('screenWindowWidth','float',struct.pack('<f',1.0))+b'\0'
    start=len(hdr)+8*h; blocks=[]; offs=[]; pos=start
    for y in range(h):
        data=a[y].astype('<f4').tobytes(); b=struct.pack('<ii',y,len(data))+data
        offs.append(pos); pos+=len(b); blocks.append(b)
    open(path,'wb').write(hdr+b''.join(struct.pack('<Q',o) for o in offs)+b''.join(blocks))
n=8
for i in range(n):
    rgb=Image.open(f'{D}/rgb/{10+i:06d}.png').convert('RGB').resize((1920,1440),Image.BICUBIC)
    rgb.save(f'{out}/rgb/{i}.jpg',quality=90)
    d=np.array(Image.open(f'{D}/depth/{10+i:06d}.png')).astype(np.float32)/1000.0
    small=d[(np.arange(192)*2.5+1).astype(int)][:,(np.arange(256)*2.5+1).astype(int)]
    write_exr(f'{out}/depth/{i}.exr', small)
json.dump({"w":1920,"h":1440,"dw":256,"dh":192,"fps":30,"K":[1450.0,0,0,0,1450.0,0,959.5,719.5,1],"frameTimestamps":[i/30 for i in range(n)],"poses":[]},open(out+'/metadata.json','w'))
print(f'{n} frames in {out}')
