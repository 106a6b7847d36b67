"""Estimate (not a bound) of the energy one hop can gain through the leg spring.

The body gains `k * integral(x dp)` over a stance (`x` leg compression, `p`
nut position): see docs/beat-the-thesis.md. This script finds the periodic
nut motion that maximises it for a hop of apex H, with

* the nut driven by the motor (current limit I, default 33.67 A = 1 N m)
  against the spring: `alpha pdd = u F - k (delta0 + x + p)`, `|u| <= 1`,
  piecewise constant on 12 stance and 24 flight segments;
* the stance compression fixed to the passive one, `x = X sin(pi t / T)`,
  `T = pi sqrt((M + m_s)/k)`, `X` from the energy of a drop from H;
* the flight `2 sqrt(2 H / g)` long, the nut inside its 50 mm stroke, and
  the motion periodic (same nut state at every touchdown).

Design parameters (thesis Table 2.1). It ignores friction on the nut and the
back-EMF limit, which only lower what is reachable, but also the upper
stop's reaction (here the motor must hold the nut off the stop against the
spring) and the nut's back-action on the body, so its optimum is an
estimate, not a bound in either direction (docs/beat-the-thesis.md). Usage (needs numpy and scipy):

    python3 docs/analysis/nut_cycle_bound.py H [CURRENT_LIMIT_A]
"""
import numpy as np
from scipy.optimize import minimize
import sys
# design params
M=9.0; ms=0.25; J=2.7e-4; lead=0.005; k=11000.; d0=0.005; eta=0.9; km=0.0297
I=float(sys.argv[2]) if len(sys.argv)>2 else 33.67
r=lead/(2*np.pi); alpha=J/r**2+ms; F=eta*km*I/r
H=float(sys.argv[1]) if len(sys.argv)>1 else 0.05
g=9.81
T=np.pi*np.sqrt((M+ms)/k)
# max compression of passive stance
a=k/2; b=k*d0-(M+ms)*g; c=-(M+ms)*g*H
X=(-b+np.sqrt(b*b-4*a*c))/(2*a)
Tf=2*np.sqrt(2*H/g)
Ns,Nf=12,24
dt_s=T/Ns/20; dt_f=Tf/Nf/20
def cycle(u, p, v, gain=False):
    G=0.0; pmin=p; pmax=p
    for i in range(Ns):
        for j in range(20):
            t=(i*20+j+0.5)*dt_s
            x=X*np.sin(np.pi*t/T)
            acc=(u[i]*F-k*(d0+x+p))/alpha
            v2=v+acc*dt_s; p2=p+0.5*(v+v2)*dt_s
            G+=k*x*(p2-p); p,v=p2,v2
            pmin=min(pmin,p); pmax=max(pmax,p)
    for i in range(Nf):
        for j in range(20):
            acc=(u[Ns+i]*F-k*(d0+p))/alpha
            v2=v+acc*dt_f; p2=p+0.5*(v+v2)*dt_f
            p,v=p2,v2
            pmin=min(pmin,p); pmax=max(pmax,p)
    return p,v,G,pmin,pmax
def orbit(u):
    # affine map: fixed point via 3 evaluations
    p0,v0,_,_,_=cycle(u,0.0,0.0)
    p1,v1,_,_,_=cycle(u,1e-3,0.0)
    p2,v2,_,_,_=cycle(u,0.0,1e-3)
    A=np.array([[(p1-p0)/1e-3,(p2-p0)/1e-3],[(v1-v0)/1e-3,(v2-v0)/1e-3]])
    bvec=np.array([p0,v0])
    z=np.linalg.solve(np.eye(2)-A,bvec)
    return z
def obj(u):
    z=orbit(u)
    p,v,G,pmin,pmax=cycle(u,z[0],z[1])
    pen=1e4*(max(0,-pmin)**2+max(0,pmax-0.05)**2)*1e4
    return -G+pen
best=None
rng=np.random.default_rng(0)
for trial in range(6):
    u0=rng.uniform(-1,1,Ns+Nf)
    res=minimize(obj,u0,bounds=[(-1,1)]*(Ns+Nf),method='L-BFGS-B',options={'maxiter':300})
    if best is None or res.fun<best.fun: best=res
z=orbit(best.x); p,v,G,pmin,pmax=cycle(best.x,z[0],z[1])
print(f"H={H} X={X:.4f} T={T:.4f} Tf={Tf:.3f} F={F:.0f} N: max gain {G:.2f} J, p range {pmin*1000:.1f}..{pmax*1000:.1f} mm, touchdown v {z[1]:.3f}")
print(np.round(best.x,2))
