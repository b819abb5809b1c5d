#!/usr/bin/env python3
# The --ptex-max measurement (docs/shading.md "Ptex textures"):
#   python3 tools/ptex_measure.py 10000 /tmp/m    # writes /tmp/m/m.ptx and /tmp/m/m.pbrt
#   for n in 1 4 16 64; do motu import /tmp/m/m.pbrt -o /tmp/m/$n.motu --ptex-max $n; \
#     motu info /tmp/m/$n.motu --json | grep ptex_bytes; done
# Writes a Ptex file like Moana's: F quad faces, resolutions 2^2..2^7 a side (log-uniform),
# u8 RGB, a fifth constant, the rest zipped; plus a pbrt-v3 scene of an F-quad grid using it.
import struct, zlib, random, sys
F = int(sys.argv[1]); out = sys.argv[2]
random.seed(1)
info=b''; const=b''; hdrs=b''; blocks=b''
for f in range(F):
    if f % 5 == 0:
        u=v=random.randint(2,7); c=bytes([random.randrange(256) for _ in range(3)])
        info += bytes([u,v,0,1]) + b'\xff'*16; const += c
        blk = c; enc = 0
    else:
        u=random.randint(2,7); v=max(2,min(7,u+random.randint(-1,1)))
        n=(1<<u)*(1<<v)
        planes=b''.join(bytes([(i*7+ch*50+f)%256 for i in range(n)]) for ch in range(3))
        info += bytes([u,v,0,0]) + b'\xff'*16; const += planes[:1]+planes[n:n+1]+planes[2*n:2*n+1]
        blk = zlib.compress(planes); enc = 1
    hdrs += struct.pack('<I', len(blk) | enc<<30); blocks += blk
iz, cz, hz = zlib.compress(info), zlib.compress(const), zlib.compress(hdrs)
lvl = len(hz)+len(blocks)
h = b'Ptex' + struct.pack('<IIIiHHIIIIII', 1, 1, 0, -1, 3, 1, F, 40, len(iz), len(cz), 16, 0)
h += struct.pack('<QII', lvl, 0, 0)
assert len(h)==64
data = h + b'\0'*40 + iz + cz + struct.pack('<QII', lvl, len(hz), F) + hz + blocks + b'\0'*8
open(out+'/m.ptx','wb').write(data)
side=int(F**0.5)
P=[];I=[];FI=[]
for z in range(side):
    for x in range(side):
        b=len(P)//3
        P += [x,0,z, x+1,0,z, x+1,0,z+1, x,0,z+1]
        I += [b,b+1,b+2, b,b+2,b+3]
        f=x+side*z; FI += [f,f]
open(out+'/m.pbrt','w').write('LookAt %d 40 %d  %d 0 %d 0 0 1\nCamera "perspective" "float fov" [60]\nWorldBegin\nTexture "t" "color" "ptex" "string filename" "m.ptx"\nMaterial "matte" "texture Kd" "t"\nShape "trianglemesh" "point P" [%s] "integer indices" [%s] "integer faceIndices" [%s]\n' % (side//2, side//2, side//2, side//2, ' '.join(map(str,P)), ' '.join(map(str,I)), ' '.join(map(str,FI))))
print(len(data), 'bytes,', F, 'faces')
