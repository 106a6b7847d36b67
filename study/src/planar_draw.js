// The planar machine drawn into an <svg> 800 x 420 from one frame
// [t, x, z, phi, theta, leg length, stance] (s, m, m, rad, rad, m, 1 on
// the ground): the ground with a mark every 0.5 m, the leg from the hip
// to the toe (thicker and red on the ground), the body as a bar pitched
// by phi, the hip (#p-hip) at its height. The view follows the hip. One
// drawing for the recorded run (run.html) and the live one
// (`hopper-sim planar serve`).
function planarLine(x1, y1, x2, y2, w, c, extra) {
  return `<line x1="${x1}" y1="${y1}" x2="${x2}" y2="${y2}" stroke="${c}" stroke-width="${w}" stroke-linecap="round" ${extra || ""}/>`;
}
function drawPlanar(svg, f) {
  const [t, x, z, phi, th, l, stance] = f;
  const S = 400, gy = 380, cx = 400; // px per m, the ground's row, the hip's column
  const X = q => cx + (q - x) * S, Y = q => gy - q * S;
  let s = planarLine(0, gy, 800, gy, 2, "#555");
  for (let m = Math.floor((x - 1) * 2) / 2; m < x + 1; m += 0.5)
    s += planarLine(X(m), gy, X(m), gy + 10, 1, "#555") + `<text x="${X(m) + 2}" y="${gy + 24}" font-size="11">${m.toFixed(1)} m</text>`;
  const hx = X(x), hy = Y(z);
  const tx = X(x + l * Math.sin(th)), ty = Y(z - l * Math.cos(th));
  const on = stance > 0.5;
  s += planarLine(hx, hy, tx, ty, on ? 7 : 5, on ? "#c62828" : "#1565c0", `id="p-leg" class="${on ? "stance" : "flight"}"`);
  s += `<circle cx="${tx}" cy="${ty}" r="6" fill="#333"/>`;
  const bw = 0.5 * S, bx = Math.cos(phi) * bw / 2, by = Math.sin(phi) * bw / 2;
  s += planarLine(hx - bx, hy + by, hx + bx, hy - by, 18, "#455a64");
  s += `<circle id="p-hip" cx="${hx}" cy="${hy.toFixed(1)}" r="5" fill="#fff" stroke="#000"/>`;
  svg.innerHTML = s;
}
