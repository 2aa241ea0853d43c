// Drives headless Chromium (Debian's, WebGPU on SwiftShader) through the
// demo in a directory (argument 1, e.g. target/web) and writes screenshots
// to another (argument 2). Asserts what the issue asks: 100 steps, finite,
// no error, the cloth out of the sphere, the canvas drawn and moving; and,
// with navigator.gpu removed before the page loads, an error that says so.
// Exit code 1 with one line per failure; any missing piece fails.
import { createServer } from 'node:http';
import { readFile, mkdir } from 'node:fs/promises';
import { extname, join, normalize } from 'node:path';
import puppeteer from 'puppeteer-core';

const [root, out] = [process.argv[2] ?? 'target/web', process.argv[3] ?? 'target/web-test'];
const STEPS = 100;
// The thickness band plus what one step's contact lets through (metres).
const DEEPEST = 0.02;

const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm' };
const server = createServer(async (req, res) => {
  const path = normalize(new URL(req.url, 'http://x').pathname).replace(/^\/+/, '') || 'index.html';
  try {
    const body = await readFile(join(root, path));
    res.writeHead(200, { 'content-type': types[extname(path)] ?? 'application/octet-stream' });
    res.end(body);
  } catch {
    res.writeHead(404);
    res.end();
  }
});
await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
const url = `http://127.0.0.1:${server.address().port}/index.html`;
await mkdir(out, { recursive: true });

const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
  headless: true,
  args: ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan',
         '--use-vulkan=swiftshader', '--use-angle=vulkan', '--window-size=900,1000'],
});
const failures = [];
const check = (ok, what) => { if (!ok) failures.push(what); };
const status = (page) => page.$eval('#status', (e) => JSON.parse(e.textContent));

try {
  const page = await browser.newPage();
  await page.setViewport({ width: 900, height: 1000 });
  page.on('console', (m) => console.log(`page: ${m.text()}`));
  page.on('pageerror', (e) => console.log(`page error: ${e.message}`));
  const started = Date.now();
  await page.goto(`${url}?model=friction-net&grid=32`);
  await page.waitForFunction(
    (n) => { const s = JSON.parse(document.getElementById('status').textContent); return s.steps >= n || s.error; },
    { timeout: 600_000, polling: 500 }, STEPS);
  let s = await status(page);
  console.log(`after ${((Date.now() - started) / 1000).toFixed(1)} s: ${JSON.stringify(s)}`);
  check(s.error === null, `error: ${s.error}`);
  check(s.steps >= STEPS, `only ${s.steps} steps`);
  check(s.finite === true, 'the state is not finite');
  check(s.model === 'friction-net', `model ${s.model}`);
  // The choices come from the library's models, each one.
  const offered = await page.$$eval('#model option', (os) => os.map((o) => o.value));
  check(offered[0] === 'friction-net' && offered.includes('naive-net'), `offered ${offered}`);
  check(await page.$eval('#model', (e) => e.value) === 'friction-net', 'friction-net not selected');
  check(typeof s.adapter === 'string' && s.adapter.length > 0, 'no adapter named');
  check(s.deepest < DEEPEST, `a vertex ${s.deepest} m inside the sphere`);
  const canvas = await page.$('#canvas');
  const first = await canvas.screenshot({ path: join(out, 'canvas.png') });
  await new Promise((ok) => setTimeout(ok, 1000));
  const second = await canvas.screenshot({ path: join(out, 'canvas_later.png') });
  await page.screenshot({ path: join(out, 'page.png') });
  check(!first.equals(second), 'the canvas did not change in a second');
  // Drawn: the screenshot holds the cloth (red dominant) and the sphere
  // (blue dominant) on the white the page clears to.
  const shares = await page.evaluate(async (png) => {
    const img = new Image();
    img.src = `data:image/png;base64,${png}`;
    await img.decode();
    const g = new OffscreenCanvas(img.width, img.height).getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, img.width, img.height).data;
    let [cloth, body] = [0, 0];
    for (let i = 0; i < d.length; i += 4) {
      const [r, gr, b] = [d[i], d[i + 1], d[i + 2]];
      if (r > gr + 40 && r > b + 40) cloth++;
      if (b > r + 40 && b > gr + 20) body++;
    }
    const n = d.length / 4;
    return { cloth: cloth / n, body: body / n };
  }, first.toString('base64'));
  console.log(`share of the canvas: cloth ${shares.cloth.toFixed(3)}, sphere ${shares.body.toFixed(3)}`);
  check(shares.cloth > 0.02, `no cloth drawn (${shares.cloth} of the canvas)`);
  check(shares.body > 0.005, `no sphere drawn (${shares.body} of the canvas)`);
  s = await status(page);
  console.log(`steps per second (the page's): ${s.steps_per_second}`);

  // A choice the page does not offer: one clear error, nothing stepped.
  const wrong = await browser.newPage();
  await wrong.goto(`${url}?model=bogus`);
  await wrong.waitForFunction(() => JSON.parse(document.getElementById('status').textContent).error,
    { timeout: 60_000 });
  const w = await status(wrong);
  console.log(`with ?model=bogus: ${JSON.stringify(w)}`);
  check(/model=bogus/.test(w.error) && w.steps === 0, `error for a bad model: ${w.error}`);

  const bare = await browser.newPage();
  await bare.evaluateOnNewDocument(() => { delete Navigator.prototype.gpu; });
  await bare.goto(url);
  await bare.waitForFunction(() => JSON.parse(document.getElementById('status').textContent).error,
    { timeout: 60_000 });
  const e = await status(bare);
  console.log(`without navigator.gpu: ${JSON.stringify(e)}`);
  check(/WebGPU/.test(e.error) && /navigator\.gpu/.test(e.error), `error without WebGPU: ${e.error}`);
  const shown = await bare.$eval('#message', (m) => m.textContent);
  check(shown === e.error, 'the error is not shown on the page');
} catch (e) {
  failures.push(`the browser run failed: ${e.message}`);
} finally {
  await browser.close();
  server.close();
}
if (failures.length) {
  for (const f of failures) console.log(`FAIL: ${f}`);
  process.exit(1);
}
console.log(`browser: ok (screenshots in ${out})`);
