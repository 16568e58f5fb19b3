"""The drive's time series as a zoomable chart: a canvas per signal on one time axis, drawn by a
small embedded script from data embedded in the page (no network, no library).

Wheel zooms the time axis around the pointer, dragging pans, a double click shows the whole drive.
A long log is averaged into at most `MAX_POINTS` samples per signal so the page stays small.
"""

from __future__ import annotations

import json

import numpy as np

MAX_POINTS = 6_000
"""Samples per signal embedded in the page (a one-day log: one per 14 s)."""

_SCRIPT = r"""
(function(){
const data=document.currentScript.previousElementSibling, root=data.previousElementSibling, d=JSON.parse(data.textContent);
const t=d.time_min||d.panels[0].lines[0].values.map((_,i)=>d.t0_min+i*d.dt_min), n=t.length; let x0=t[0], x1=t[n-1]; const full=[x0,x1];
const panels=d.panels.map(p=>{const c=document.createElement('canvas');c.width=1000;c.height=150;
  c.style.width='100%';c.style.display='block';root.appendChild(c);return {p,c};});
function lower(x){let a=0,b=n;while(a<b){const m=(a+b)>>1;if(t[m]<x)a=m+1;else b=m;}return a;}
function ticks(lo,hi,k){const step=Math.pow(10,Math.floor(Math.log10((hi-lo)/k||1)));
  const s=[1,2,5,10].map(f=>f*step).find(v=>(hi-lo)/v<=k)||step*10;const out=[];
  for(let v=Math.ceil(lo/s)*s;v<=hi+1e-9;v+=s)out.push(+v.toFixed(10));return out;}
function draw(){let drawn=0;const i0=Math.max(lower(x0)-1,0),i1=Math.min(lower(x1)+1,n);
  panels.forEach(({p,c},k)=>{const g=c.getContext('2d'),L=70,R=10,T=p.lines.length>1?22:8,B=k==panels.length-1?28:8;
    const W=c.width-L-R,H=c.height-T-B;g.clearRect(0,0,c.width,c.height);g.font='12px sans-serif';
    let lo=Infinity,hi=-Infinity;p.lines.forEach(l=>{for(let i=i0;i<i1;i++){const v=l.values[i];
      if(v!==null){if(v<lo)lo=v;if(v>hi)hi=v;}}});
    if(!(hi>=lo)){lo=0;hi=1;}if(hi-lo<1e-9){lo-=1;hi+=1;}const pad=0.05*(hi-lo);lo-=pad;hi+=pad;
    const X=x=>L+(x-x0)/(x1-x0)*W,Y=v=>T+H-(v-lo)/(hi-lo)*H;
    g.strokeStyle='#d0d7de';g.fillStyle='#57606a';g.lineWidth=1;
    ticks(lo,hi,6).forEach(v=>{g.beginPath();g.moveTo(L,Y(v));g.lineTo(L+W,Y(v));g.stroke();
      g.textAlign='right';g.fillText(String(v),L-4,Y(v)+4);});
    ticks(x0,x1,10).forEach(v=>{g.beginPath();g.moveTo(X(v),T);g.lineTo(X(v),T+H);g.stroke();
      if(B>8){g.textAlign='center';g.fillText(String(v),X(v),T+H+14);}});
    g.strokeRect(L,T,W,H);g.save();g.translate(12,T+H/2);g.rotate(-Math.PI/2);g.textAlign='center';
    g.fillText(p.label,0,0);g.restore();if(B>8){g.textAlign='right';g.fillText('time [min]',L+W,T+H+26);}
    g.save();g.beginPath();g.rect(L,T,W,H);g.clip();
    p.lines.forEach(l=>{g.strokeStyle=l.colour;g.beginPath();let up=true;
      for(let i=i0;i<i1;i++){const v=l.values[i];if(v===null){up=true;continue;}
        const x=X(t[i]),y=Y(v);if(up)g.moveTo(x,y);else g.lineTo(x,y);up=false;drawn++;}g.stroke();});
    g.restore();if(p.lines.length>1){let x=L+8;p.lines.filter(l=>l.name).forEach(l=>{g.fillStyle=l.colour;
      g.textAlign='left';g.fillText(l.name,x,T-7);x+=g.measureText(l.name).width+24;});}});
  root.dataset.drawn=drawn;}
function zoom(f,at){const a=at-(at-x0)*f,b=at+(x1-at)*f;x0=Math.max(full[0],a);x1=Math.min(full[1],b);
  if(x1-x0<1/60){x1=x0+1/60;}draw();}
panels.forEach(({c})=>{const at=e=>{const r=c.getBoundingClientRect(),W=r.width*(c.width-80)/c.width,
    L=r.width*70/c.width;return x0+(e.clientX-r.left-L)/W*(x1-x0);};
  c.addEventListener('wheel',e=>{e.preventDefault();zoom(e.deltaY>0?1.25:0.8,at(e));},{passive:false});
  c.addEventListener('dblclick',()=>{[x0,x1]=full;draw();});
  c.addEventListener('mousedown',e=>{let last=at(e);const move=m=>{const now=at(m),dx=last-now;
      const w=x1-x0;x0=Math.min(Math.max(full[0],x0+dx),full[1]-w);x1=x0+w;draw();last=at(m);};
    const up=()=>{removeEventListener('mousemove',move);removeEventListener('mouseup',up);};
    addEventListener('mousemove',move);addEventListener('mouseup',up);});});
draw();})();
"""


def _averaged(values: np.ndarray, size: int) -> np.ndarray:
    """Means of consecutive blocks of ``size`` samples (NaN where a block has no value)."""
    if size == 1:
        return values
    blocks = -(-len(values) // size)
    padded = np.full(blocks * size, np.nan)
    padded[:len(values)] = values
    padded = padded.reshape(blocks, size)
    counts = np.isfinite(padded).sum(axis=1)
    sums = np.nansum(padded, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / counts, np.nan)


def zoom_chart(time_s: np.ndarray, panels: list[tuple[str, list[tuple[str, np.ndarray, str]]]],
               max_points: int = MAX_POINTS) -> str:
    """HTML of the chart: ``panels`` is [(axis label, [(line name, values, colour), …]), …]; a
    panel of several lines names each above its plot, a line named "" shares the name before it."""
    size = max(1, -(-len(time_s) // max_points))

    def listed(values, decimals: int) -> list:
        values = np.round(_averaged(np.asarray(values, dtype=float), size), decimals)
        return [None if not np.isfinite(v) else (int(v) if decimals == 0 else float(v)) for v in values]

    def decimals(lines) -> int:
        """Enough for three significant digits of the panel's span."""
        finite = np.concatenate([np.asarray(v, dtype=float)[np.isfinite(np.asarray(v, dtype=float))]
                                 for _, v, _ in lines])
        span = float(finite.max() - finite.min()) if finite.size else 1.0
        span = span or 1.0
        return int(min(max(2 - np.floor(np.log10(span)), 0), 4))

    time_min = np.asarray(time_s, dtype=float)[::size] / 60.0  # each block at its first sample
    steps = np.diff(time_min)
    data = ({"t0_min": float(time_min[0]), "dt_min": float(steps[0])}
            if len(steps) and np.allclose(steps, steps[0], rtol=1e-6, atol=1e-9)
            else {"time_min": [round(float(t), 4) for t in time_min]})
    data["panels"] = [{"label": label, "lines": [{"name": name, "values": listed(values, decimals(lines)),
                                                   "colour": colour} for name, values, colour in lines]}
                      for label, lines in panels]
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return (f"<div class='zoom'></div><script type='application/json'>{payload}</script>"
            f"<script>{_SCRIPT}</script>")
