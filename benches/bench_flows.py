import time, numpy as np, numba as nb, physcore as pc
@nb.njit(parallel=True, fastmath=False)
def rk4(x, y, z, h, steps, s=10.0, r=28.0, b=8/3):
    n = x.size
    for _ in range(steps):
        for i in nb.prange(n):
            X, Y, Z = x[i], y[i], z[i]
            k1x = s*(Y-X); k1y = X*(r-Z)-Y; k1z = X*Y-b*Z
            X2, Y2, Z2 = X+0.5*h*k1x, Y+0.5*h*k1y, Z+0.5*h*k1z
            k2x = s*(Y2-X2); k2y = X2*(r-Z2)-Y2; k2z = X2*Y2-b*Z2
            X3, Y3, Z3 = X+0.5*h*k2x, Y+0.5*h*k2y, Z+0.5*h*k2z
            k3x = s*(Y3-X3); k3y = X3*(r-Z3)-Y3; k3z = X3*Y3-b*Z3
            X4, Y4, Z4 = X+h*k3x, Y+h*k3y, Z+h*k3z
            k4x = s*(Y4-X4); k4y = X4*(r-Z4)-Y4; k4z = X4*Y4-b*Z4
            x[i] = X + h/6*(k1x+2*k2x+2*k3x+k4x)
            y[i] = Y + h/6*(k1y+2*k2y+2*k3y+k4y)
            z[i] = Z + h/6*(k1z+2*k2z+2*k3z+k4z)
n=100_000
scene = pc.Scene(dim=3, dt=0.005, threads=2)
cloud = scene.add(pc.Flow('lorenz', points=n, spread=0.5, seed=7))
p = cloud.points; x,y,z = [np.ascontiguousarray(p[:,k]) for k in range(3)]
rk4(x,y,z,0.005,1); scene.step(1)
a=[];b=[]
for r in range(5):
    t=time.perf_counter(); scene.step(100); a.append(time.perf_counter()-t)
    t=time.perf_counter(); rk4(x,y,z,0.005,100); b.append(time.perf_counter()-t)
import statistics as st
print("physcore", n*100/st.median(a)/1e6, "numba", n*100/st.median(b)/1e6, "ratio", st.median(b)/st.median(a), pc.simd_level())
