// Overload benchmark of a running `terrabound serve` (driven by bench/load_bench.sh): loopback
// only, bounded in time and in requests.
//
// While IDLE connections sit idle and SLOW connections send a request head one line per second
// (reconnecting when the server times them out), CONCURRENCY keep-alive clients ask for cold
// tiles (every tile of every zoom and eps level of the first layer) for DURATION
// seconds or MAX_REQUESTS requests. Meanwhile one probe asks for /health and one for a cached
// tile every PROBE_MS, and the server's RSS is sampled every 500 ms.
// With RETRY_AFTER=1 a client waits the Retry-After of a 503 before its next request.
// With DISTINCT > 0 the cold tiles are a sample of that many (seeded by SEED), spread over
// every zoom. A tile refused with 503 is asked again after the others. Prints TSV lines: case,
// requests, req/s, status mix, p50 ms, p99 ms, max ms; then RSS every 5 s and a summary:
// accepted (200) p99, the share answered 503, client timeouts, and peak RSS against MEMORY_MB.
import http from 'node:http';
import net from 'node:net';
import fs from 'node:fs';
import { Worker, isMainThread, parentPort, workerData } from 'node:worker_threads';

const env = (name, dflt) => (process.env[name] === undefined ? dflt : Number(process.env[name]));
const PORT = env('PORT', 8080);
const PID = env('PID', 0);
const DURATION = env('DURATION', 20) * 1000;
const CONCURRENCY = env('CONCURRENCY', 128);
const IDLE = env('IDLE', 1000);
const SLOW = env('SLOW', 100);
const MAX_REQUESTS = env('MAX_REQUESTS', 200000);
const PROBE_MS = env('PROBE_MS', 20);
const DISTINCT = env('DISTINCT', 0);
const SEED = env('SEED', 1);
const MEMORY_MB = env('MEMORY_MB', 0);
// 1: a client that got 503 waits its Retry-After before its next request, as a viewer does;
// 0: it asks again at once (the most pressure on the server).
const RETRY_AFTER = env('RETRY_AFTER', 0);
const HOST = '127.0.0.1';

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const quantile = (v, q) => {
    if (!v.length) return NaN;
    const s = [...v].sort((a, b) => a - b);
    return s[Math.min(s.length - 1, Math.floor(q * s.length))];
};
const max_of = (v) => v.reduce((m, x) => (x > m ? x : m), -Infinity);
const rss_mb = () => {
    if (!PID) return NaN;
    try {
        const m = /VmRSS:\s+(\d+) kB/.exec(fs.readFileSync(`/proc/${PID}/status`, 'utf8'));
        return m ? Number(m[1]) / 1024 : NaN;
    } catch {
        return NaN;
    }
};

function get(agent, path) {
    return new Promise((resolve) => {
        const start = process.hrtime.bigint();
        const req = http.get({ host: HOST, port: PORT, path, agent }, (res) => {
            res.resume();
            res.on('end', () =>
                resolve({ status: res.statusCode, ms: Number(process.hrtime.bigint() - start) / 1e6,
                          retry_after: Number(res.headers['retry-after'] || 0) }));
        });
        req.setTimeout(30000, () => req.destroy(new Error('timeout')));
        req.on('error', (e) =>
            resolve({ status: 0, ms: Number(process.hrtime.bigint() - start) / 1e6, error: e.code || e.message }));
    });
}

// The probes run on a thread of their own, so that the load's event loop does not delay them:
// what they measure is the server.
if (!isMainThread) {
    const agent = new http.Agent({ keepAlive: true, maxSockets: 1 });
    const times = [];
    let probing = true;
    parentPort.on('message', () => (probing = false));
    while (probing) {
        const r = await get(agent, workerData.path);
        times.push(r.status === 200 ? r.ms : Infinity);
        await sleep(workerData.every);
    }
    parentPort.postMessage(times);
    process.exit(0);
}

async function json(path) {
    const agent = new http.Agent();
    return new Promise((resolve, reject) => {
        http.get({ host: HOST, port: PORT, path, agent }, (res) => {
            let body = '';
            res.on('data', (d) => (body += d));
            res.on('end', () => resolve(JSON.parse(body)));
        }).on('error', reject);
    });
}

// Every tile URL of the layer: zooms min..max over its bounds, glb, each eps level and the default.
function tile_urls(layer) {
    const urls = [];
    const epss = ['', ...layer.eps_levels.map((_, k) => `?eps=${k}`)];
    for (let z = layer.min_zoom; z <= layer.max_zoom; ++z) {
        const b = layer.bounds;
        let x0, x1, y0, y1;
        if (layer.scheme === 'geodetic') {
            const size = 180 / 2 ** z;
            x0 = Math.floor((b.west + 180) / size); x1 = Math.floor((b.east + 180) / size - 1e-9);
            y0 = Math.floor((b.south + 90) / size); y1 = Math.floor((b.north + 90) / size - 1e-9);
        } else {
            const n = 2 ** z;
            const tx = (lon) => Math.floor(((lon + 180) / 360) * n);
            const ty = (lat) => {
                const r = (lat * Math.PI) / 180;
                return Math.floor(((1 - Math.log(Math.tan(r) + 1 / Math.cos(r)) / Math.PI) / 2) * n);
            };
            x0 = tx(b.west); x1 = tx(b.east - 1e-9); y0 = ty(b.north - 1e-9); y1 = ty(b.south);
        }
        for (const eps of epss)
            for (let y = y0; y <= y1; ++y)
                for (let x = x0; x <= x1; ++x) urls.push(`/${layer.name}/${z}/${x}/${y}.glb${eps}`);
    }
    return urls;
}

// `count` of `v` (all when 0 or more than v has), in an order drawn from `seed`: a
// Fisher-Yates shuffle driven by mulberry32, so runs before and after a change ask the same.
function sample(v, count, seed) {
    let a = seed >>> 0;
    const random = () => {
        a = (a + 0x6d2b79f5) >>> 0;
        let t = a;
        t = Math.imul(t ^ (t >>> 15), t | 1);
        t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
        return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
    };
    const out = [...v];
    for (let i = out.length - 1; i > 0; --i) {
        const j = Math.floor(random() * (i + 1));
        [out[i], out[j]] = [out[j], out[i]];
    }
    return count > 0 ? out.slice(0, count) : out;
}

const layer = (await json('/layers')).layers[0];
const urls = tile_urls(layer);
const cached = urls[0];
const probe_agent = new http.Agent({ keepAlive: true, maxSockets: 2 });
await get(probe_agent, cached); // generated once: from now on a cache hit
const cold = DISTINCT > 0 ? sample(urls.slice(1), DISTINCT, SEED) : urls.slice(1);
if (DISTINCT > cold.length) console.error(`load_bench: only ${cold.length} distinct cold tiles`);

// Idle and slow connections; each reconnects when the server closes it (idle timeout, 408),
// so the pressure lasts the whole run.
const sockets = [];
let stopping = false;
let idle_reconnects = 0;
function idle_client() {
    if (stopping) return;
    const s = net.connect(PORT, HOST);
    s.on('error', () => {});
    s.on('close', () => {
        if (!stopping) {
            ++idle_reconnects;
            setTimeout(idle_client, 10);
        }
    });
    sockets.push(s);
}
for (let i = 0; i < IDLE; ++i) idle_client();
let slow_reconnects = 0;
function slow_client() {
    if (stopping) return;
    const s = net.connect(PORT, HOST, () => s.write('GET /health HTTP/1.1\r\nHost: x\r\n'));
    s.on('error', () => {});
    s.on('data', () => {});
    const timer = setInterval(() => s.write(`X-Slow: ${Date.now()}\r\n`), 1000);
    s.on('close', () => {
        clearInterval(timer);
        if (!stopping) {
            ++slow_reconnects;
            setTimeout(slow_client, 10);
        }
    });
    sockets.push(s);
}
for (let i = 0; i < SLOW; ++i) slow_client();
await sleep(500);

const rss = [[0, rss_mb()]];
const t0 = Date.now();
const rss_timer = setInterval(() => rss.push([(Date.now() - t0) / 1000, rss_mb()]), 500);

// The probes.
const start_probe = (path) => {
    const w = new Worker(new URL(import.meta.url), { workerData: { path, every: PROBE_MS } });
    const done = new Promise((resolve) => w.once('message', resolve));
    return { stop: () => (w.postMessage('stop'), done) };
};
const probes = [start_probe('/health'), start_probe(cached)];

// The load: cold tiles, each asked once, by CONCURRENCY keep-alive clients.
const load_agent = new http.Agent({ keepAlive: true, maxSockets: CONCURRENCY });
const statuses = new Map();
const errors = new Map(); // status 0: the request failed, by error code
const retry = []; // tiles refused with 503, asked again once the list is through
const lat = [], lat_ok = [], lat_busy = [];
let next = 0, sent = 0;
const end_at = Date.now() + DURATION;
const worker = async () => {
    while (Date.now() < end_at && sent < MAX_REQUESTS && (next < cold.length || retry.length)) {
        const url = next < cold.length ? cold[next++] : retry.shift();
        ++sent;
        const r = await get(load_agent, url);
        statuses.set(r.status, (statuses.get(r.status) || 0) + 1);
        if (r.error) errors.set(r.error, (errors.get(r.error) || 0) + 1);
        lat.push(r.ms);
        if (r.status === 200) lat_ok.push(r.ms);
        if (r.status === 503) {
            lat_busy.push(r.ms);
            retry.push(url);
            if (RETRY_AFTER && r.retry_after > 0) await sleep(r.retry_after * 1000);
        }
    }
};
await Promise.all(Array.from({ length: CONCURRENCY }, worker));
const seconds = (Date.now() - t0) / 1000;
const [health, hot] = await Promise.all(probes.map((p) => p.stop()));
clearInterval(rss_timer);
rss.push([(Date.now() - t0) / 1000, rss_mb()]);
const metrics = await new Promise((resolve) => {
    http.get({ host: HOST, port: PORT, path: '/metrics', agent: new http.Agent() }, (res) => {
        let body = '';
        res.on('data', (d) => (body += d));
        res.on('end', () => resolve(body));
    }).on('error', () => resolve(''));
});
stopping = true;
for (const s of sockets) s.destroy();

const fmt = (x) => (Number.isFinite(x) ? x.toFixed(2) : String(x));
const mix = [...statuses.entries()].sort().map(([s, n]) => `${s}:${n}`).join(',');
const gauge = (name) => (new RegExp(`^${name} (\\S+)$`, 'm').exec(metrics) || [])[1];
console.log(['case', 'requests', 'req_per_s', 'statuses', 'p50_ms', 'p99_ms', 'max_ms'].join('\t'));
console.log(['cold_tiles', sent, fmt(sent / seconds), mix, fmt(quantile(lat, 0.5)),
             fmt(quantile(lat, 0.99)), fmt(max_of(lat))].join('\t'));
console.log(['cold_tiles_200', lat_ok.length, fmt(lat_ok.length / seconds), '200',
             fmt(quantile(lat_ok, 0.5)), fmt(quantile(lat_ok, 0.99)), fmt(max_of(lat_ok))].join('\t'));
console.log(['cold_tiles_503', lat_busy.length, fmt(lat_busy.length / seconds), '503',
             fmt(quantile(lat_busy, 0.5)), fmt(quantile(lat_busy, 0.99)),
             fmt(max_of(lat_busy))].join('\t'));
const failed = (v) => v.filter((x) => !Number.isFinite(x)).length;
console.log(['health_probe', health.length, '-', `failed:${failed(health)}`, fmt(quantile(health, 0.5)),
             fmt(quantile(health, 0.99)), fmt(max_of(health))].join('\t'));
console.log(['cached_tile_probe', hot.length, '-', `failed:${failed(hot)}`, fmt(quantile(hot, 0.5)),
             fmt(quantile(hot, 0.99)), fmt(max_of(hot))].join('\t'));
console.log(['background', IDLE + SLOW, '-', `idle:${IDLE},slow:${SLOW},idle_reconnects:${idle_reconnects},slow_reconnects:${slow_reconnects}`,
             `open_at_end:${gauge('tb_http_connections')}`, `timeouts:${gauge('tb_http_timeouts_total')}`,
             `tiles_generated:${gauge('tb_tiles_generated_total')}`].join('\t'));
// RSS every 5 s (sampled every 500 ms), with the first, peak and last sample.
const rss_peak = max_of(rss.map(([, m]) => m));
const every_5s = [];
for (const sample of rss) {
    if (!every_5s.length || sample[0] >= every_5s[every_5s.length - 1][0] + 5) every_5s.push(sample);
}
if (every_5s[every_5s.length - 1] !== rss[rss.length - 1]) every_5s.push(rss[rss.length - 1]);
console.log(['rss_mb', rss.length, '-', every_5s.map(([t, m]) => `${t.toFixed(1)}s:${fmt(m)}`).join(','),
             fmt(rss[0][1]), fmt(rss_peak), fmt(rss[rss.length - 1][1])].join('\t'));
const count = (status) => statuses.get(status) || 0;
console.log(['summary', `distinct:${cold.length}`, `accepted_p99_ms:${fmt(quantile(lat_ok, 0.99))}`,
             `share_503:${fmt((100 * count(503)) / sent)}%`, `failed:${count(0)}(${[...errors.entries()].map(([e, n]) => `${e}:${n}`).join(',')})`,
             `rss_peak_mb:${fmt(rss_peak)}`,
             MEMORY_MB ? `memory_mb:${MEMORY_MB},peak/budget:${fmt(rss_peak / MEMORY_MB)}` : 'memory_mb:none',
             `deadline_expiries:${gauge('tb_deadline_expiries_total') ?? '-'}`,
             `generations_cancelled:${gauge('tb_generations_cancelled_total') ?? '-'}`].join('\t'));
process.exit(0);
