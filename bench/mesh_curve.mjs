// Triangles against time per bench case, as an SVG: our effort levels joined as a curve, hmm
// and delatin as marks. Reads bench/mesh_bench.sh's TSV (bench/runs/mesh_bench.tsv) on stdin,
// writes the SVG to stdout. Both axes are ratios to hmm's (to delatin's when the table has no
// hmm): hmm sits at (1, 1), down is fewer triangles, left is faster.
//
//   node bench/mesh_curve.mjs < bench/runs/mesh_bench.tsv > bench/runs/curve.svg
import { readFileSync } from 'node:fs';

const rows = readFileSync(0, 'utf8').trim().split('\n').map((l) => l.split('\t'));
const head = rows.shift();
const col = Object.fromEntries(head.map((name, i) => [name, i]));
const num = (r, name) => (r[col[name]] === '-' ? NaN : Number(r[col[name]]));

const cases = new Map(); // "input eps" -> {levels: [{effort, ms, tris}], hmm, delatin}
for (const r of rows) {
    const key = `${r[col.input]} ε ${r[col.eps]}`;
    if (!cases.has(key)) {
        cases.set(key, {
            levels: [],
            hmm: { ms: num(r, 'hmm_ms'), tris: num(r, 'hmm_triangles') },
            delatin: { ms: num(r, 'delatin_ms'), tris: num(r, 'delatin_triangles') },
        });
    }
    cases.get(key).levels.push({ effort: r[col.effort], ms: num(r, 'ms'), tris: num(r, 'triangles') });
}
const order = ['fast', 'balanced', 'best'];
const colour = { fast: '#d95f02', balanced: '#7570b3', best: '#1b9e77' };

const W = 300, H = 240, M = { l: 48, r: 46, t: 26, b: 36 }, per = 3;
const n = cases.size, width = per * W, height = Math.ceil(n / per) * H + 40;
const out = [];
out.push(`<svg xmlns="http://www.w3.org/2000/svg" width="${width}" height="${height}" ` +
    `font-family="sans-serif" font-size="11">`);
out.push(`<rect width="100%" height="100%" fill="white"/>`);
let k = 0;
for (const [key, c] of cases) {
    const ref = Number.isFinite(c.hmm.ms) ? c.hmm : c.delatin;
    const refName = Number.isFinite(c.hmm.ms) ? 'hmm' : 'delatin';
    const pts = c.levels
        .sort((a, b) => order.indexOf(a.effort) - order.indexOf(b.effort))
        .map((l) => ({ ...l, x: l.ms / ref.ms, y: l.tris / ref.tris }));
    const peers = [['hmm', c.hmm], ['delatin', c.delatin]]
        .filter(([, p]) => Number.isFinite(p.ms))
        .map(([name, p]) => ({ name, x: p.ms / ref.ms, y: p.tris / ref.tris }));
    const all = [...pts, ...peers];
    const xmax = Math.max(1.2, ...all.map((p) => p.x)) * 1.1;
    const ymax = Math.max(1.2, ...all.map((p) => p.y)) * 1.1;
    const ox = (k % per) * W, oy = Math.floor(k / per) * H;
    const px = (x) => ox + M.l + (x / xmax) * (W - M.l - M.r);
    const py = (y) => oy + H - M.b - (y / ymax) * (H - M.t - M.b);
    out.push(`<text x="${ox + M.l}" y="${oy + 16}" font-weight="bold">${key}</text>`);
    for (let g = 0; g <= xmax; g += 0.5) {
        out.push(`<line x1="${px(g)}" y1="${py(0)}" x2="${px(g)}" y2="${py(ymax)}" ` +
            `stroke="${g === 1 ? '#999' : '#eee'}"/>`);
        out.push(`<text x="${px(g)}" y="${py(0) + 13}" text-anchor="middle">${g}</text>`);
    }
    for (let g = 0; g <= ymax; g += 0.25) {
        out.push(`<line x1="${px(0)}" y1="${py(g)}" x2="${px(xmax)}" y2="${py(g)}" ` +
            `stroke="${g === 1 ? '#999' : '#eee'}"/>`);
        out.push(`<text x="${px(0) - 4}" y="${py(g) + 4}" text-anchor="end">${g}</text>`);
    }
    out.push(`<text x="${ox + W / 2}" y="${oy + H - 6}" text-anchor="middle">` +
        `time / ${refName}'s</text>`);
    out.push(`<text transform="translate(${ox + 11} ${oy + H / 2}) rotate(-90)" ` +
        `text-anchor="middle">triangles / ${refName}'s</text>`);
    out.push(`<polyline fill="none" stroke="#555" points="` +
        pts.map((p) => `${px(p.x).toFixed(1)},${py(p.y).toFixed(1)}`).join(' ') + `"/>`);
    for (const p of pts) {
        out.push(`<circle cx="${px(p.x)}" cy="${py(p.y)}" r="4" fill="${colour[p.effort] ?? '#000'}">` +
            `<title>${p.effort}: ${p.tris} triangles, ${p.ms} ms</title></circle>`);
    }
    for (const p of peers) {
        const x = px(p.x), y = py(p.y);
        out.push(p.name === 'hmm'
            ? `<rect x="${x - 4}" y="${y - 4}" width="8" height="8" fill="none" stroke="black"/>`
            : `<path d="M${x} ${y - 5}L${x + 5} ${y}L${x} ${y + 5}L${x - 5} ${y}Z" fill="none" ` +
              `stroke="#e7298a"/>`);
        out.push(`<text x="${x + 6}" y="${y - 5}">${p.name}</text>`);
    }
    ++k;
}
const ly = height - 16;
let lx = 12;
for (const e of order) {
    out.push(`<circle cx="${lx}" cy="${ly - 4}" r="4" fill="${colour[e]}"/>` +
        `<text x="${lx + 8}" y="${ly}">${e}</text>`);
    lx += 80;
}
out.push(`<rect x="${lx - 4}" y="${ly - 8}" width="8" height="8" fill="none" stroke="black"/>` +
    `<text x="${lx + 8}" y="${ly}">hmm</text>`);
lx += 60;
out.push(`<path d="M${lx} ${ly - 9}L${lx + 5} ${ly - 4}L${lx} ${ly + 1}L${lx - 5} ${ly - 4}Z" ` +
    `fill="none" stroke="#e7298a"/><text x="${lx + 8}" y="${ly}">delatin</text>`);
out.push(`<text x="${lx + 80}" y="${ly}">best of N per mesher, same run; both axes / hmm's</text>`);
out.push('</svg>');
console.log(out.join('\n'));
