#!/usr/bin/env node
// The relighting page in headless Chromium against a real `pmsc view`.
//
//   node tests/relight.mjs --model D/model.pmsc --scene volume:D/density.vdb [--bin build/bin/pmsc]
//        [--moves 100 | --short] [--out DIR] [--size 480x360] [--tolerance 0] [--url URL]
//        [--gpu-compositing] [--trace FILE]
//
// Starts the server itself (--port 0, the address it prints), drives the page through
// window.pmscView, prints a JSON summary and exits 1 if any check failed (2: could not run).
// Environment: PMSC_BIN, PMSC_VIEW_MODEL, PMSC_VIEW_SCENE, CHROMIUM (default /usr/bin/chromium).

import {spawn} from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import {fileURLToPath} from 'node:url';
import puppeteer from 'puppeteer-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const webDir = path.resolve(here, '..');
const repoDir = path.resolve(webDir, '../..');

function parseArgs(argv) {
  const options = {
    bin: process.env.PMSC_BIN || path.join(repoDir, 'build/bin/pmsc'),
    model: process.env.PMSC_VIEW_MODEL,
    scene: process.env.PMSC_VIEW_SCENE,
    moves: 100,
    out: path.resolve('relight-out'),
    size: '480x360',
    tolerance: 0,
    url: null,
    chromium: process.env.CHROMIUM || '/usr/bin/chromium',
    timeout: 60000,
    gpuCompositing: false,
    trace: null,
  };
  for (let i = 2; i < argv.length; ++i) {
    const arg = argv[i];
    const value = () => {
      if (i + 1 >= argv.length) throw new Error(`${arg} needs a value`);
      return argv[++i];
    };
    if (arg === '--bin') options.bin = value();
    else if (arg === '--model') options.model = value();
    else if (arg === '--scene') options.scene = value();
    else if (arg === '--moves') options.moves = Number(value());
    else if (arg === '--short') options.moves = 20;
    else if (arg === '--out') options.out = path.resolve(value());
    else if (arg === '--size') options.size = value();
    else if (arg === '--tolerance') options.tolerance = Number(value());
    else if (arg === '--url') options.url = value();
    else if (arg === '--chromium') options.chromium = value();
    else if (arg === '--gpu-compositing') options.gpuCompositing = true;
    else if (arg === '--trace') options.trace = path.resolve(value());
    else if (arg === '--help' || arg === '-h') {
      console.log(fs.readFileSync(fileURLToPath(import.meta.url), 'utf8').split('\n').slice(1, 11).join('\n'));
      process.exit(0);
    } else throw new Error(`unknown argument ${arg}`);
  }
  if (!options.url && (!options.model || !options.scene)) throw new Error('--model and --scene (or --url) are required');
  if (!(options.moves >= 1)) throw new Error('--moves must be at least 1');
  return options;
}

/** Starts `pmsc view ... --port 0` and resolves with {process, url} once it prints its address. */
function startServer(options) {
  const args = ['view', '--model', options.model, '--scene', options.scene, '--port', '0', '--web', webDir];
  const child = spawn(options.bin, args, {stdio: ['ignore', 'pipe', 'pipe']});
  let stderr = '';
  child.stderr.on('data', d => { stderr += d; });
  return new Promise((resolve, reject) => {
    let stdout = '';
    const timer = setTimeout(() => { child.kill('SIGTERM'); reject(new Error(`pmsc view printed no address within ${options.timeout / 1000} s: ${stderr.trim()}`)); }, options.timeout);
    child.on('error', error => { clearTimeout(timer); reject(new Error(`cannot start ${options.bin}: ${error.message}`)); });
    child.on('exit', code => { clearTimeout(timer); reject(new Error(`pmsc view exited (${code}) before listening: ${stderr.trim()}`)); });
    child.stdout.on('data', d => {
      stdout += d;
      const match = stdout.match(/^pmsc view: (http:\/\/\S+\/)$/m);
      if (match) {
        clearTimeout(timer);
        child.removeAllListeners('exit');
        resolve({process: child, url: match[1], stderr: () => stderr});
      }
    });
  });
}

const percentile = (values, q) => {
  if (values.length === 0) return null;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.min(sorted.length - 1, Math.max(0, Math.ceil(q * sorted.length) - 1))];
};
const round = x => (x === null || x === undefined ? x : Math.round(x * 10) / 10);
const summary = values => ({count: values.length, p50: round(percentile(values, 0.5)), p95: round(percentile(values, 0.95)), max: round(percentile(values, 1))});

/** A drag: each control with range moves on a smooth closed path around its default, small steps. */
function dragPath(controls, moves) {
  const path = [];
  for (let m = 1; m <= moves; ++m) {
    const t = m / moves;
    const values = {};
    controls.forEach((c, k) => {
      const range = c.max - c.min;
      const amplitude = (k === 0 ? 0.08 : k === 1 ? 0.05 : 0.03) * range;
      const v = c.value + amplitude * Math.sin(2 * Math.PI * t * (k === 1 ? 2 : 1) + k);
      const stepped = Math.round((v - c.min) / c.step) * c.step + c.min;
      values[c.name] = Math.min(c.max, Math.max(c.min, Number(stepped.toFixed(6))));
    });
    path.push(values);
  }
  return path;
}

/** Control settings far from the defaults, the most likely first: where a miss is looked for. */
function missCandidates(scene) {
  const byName = Object.fromEntries(scene.controls.map(c => [c.name, c]));
  const defaults = Object.fromEntries(scene.controls.map(c => [c.name, c.value]));
  const candidates = [];
  if (scene.kind === 'volume' && byName.elevation) {
    candidates.push({...defaults, elevation: byName.elevation.min});
    candidates.push({...defaults, elevation: Math.min(byName.elevation.max, 89)});
  }
  // Each control alone at its ends, then every corner of the controls' box.
  for (const c of scene.controls) for (const v of [c.min, c.max]) candidates.push({...defaults, [c.name]: v});
  let corners = [{}];
  for (const c of scene.controls) corners = corners.flatMap(k => [{...k, [c.name]: c.min}, {...k, [c.name]: c.max}]);
  candidates.push(...corners);
  const seen = new Set();
  return candidates.filter(c => {
    const key = JSON.stringify(c);
    return !seen.has(key) && seen.add(key);
  });
}

async function main() {
  let options;
  try {
    options = parseArgs(process.argv);
  } catch (error) {
    console.error(`relight: ${error.message}`);
    process.exit(2);
  }
  fs.mkdirSync(options.out, {recursive: true});
  const checks = [];
  const check = (name, ok, detail) => {
    checks.push({name, ok: Boolean(ok), ...(detail === undefined ? {} : {detail})});
    if (!ok) console.error(`relight: FAILED ${name}${detail === undefined ? '' : `: ${JSON.stringify(detail)}`}`);
  };
  const result = {url: null, moves: options.moves, compositing: options.gpuCompositing ? 'gpu (SwiftShader)' : 'software',
    checks, screenshots: {}};

  if (!fs.existsSync(options.chromium)) throw new Error(`no browser at ${options.chromium} (apt-get install chromium)`);
  const server = options.url ? null : await startServer(options);
  const url = options.url || server.url;
  result.url = url;
  let serverExit = null;
  server?.process.on('exit', (code, signal) => { serverExit = {code, signal}; });

  const browser = await puppeteer.launch({
    executablePath: options.chromium,
    headless: true,
    // No DevTools Network domain: with it on, Chromium copies every response body and WebSocket
    // message for the inspector, on the page's main thread (about 30 ms for a whole volume cache on a
    // 2-core machine), a cost a user's browser does not pay.
    networkEnabled: false,
    // Chromium's own set-up on a machine without a GPU (SystemInfo.getInfo: gpu_compositing
    // "disabled_software"): WebGL 2 in SwiftShader, the page composited in software.
    // --gpu-compositing forces compositing through SwiftShader as well (--use-angle=swiftshader
    // --ignore-gpu-blocklist), which costs the 2-core machine about 15 ms of CPU per frame.
    args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--disable-background-timer-throttling',
      '--disable-renderer-backgrounding',
      ...(options.gpuCompositing ? ['--use-angle=swiftshader', '--ignore-gpu-blocklist'] : [])],
  });
  try {
    const page = await browser.newPage();
    await page.setViewport({width: 880, height: 640});
    const pageErrors = [];
    page.on('pageerror', error => pageErrors.push(error.message));
    page.on('console', message => { if (message.type() === 'error' && !/favicon/.test(message.location()?.url || '')) pageErrors.push(message.text()); });
    const pageUrl = `${url}?size=${options.size}`;
    await page.goto(pageUrl);
    const ready = await page.evaluate(() => window.pmscView.ready.then(r => r, e => ({error: e.message})));
    check('page ready (scene, geometry, hello, first image)', !ready.error && ready.checksumOk, ready);
    if (ready.error) throw new Error(`page did not start: ${ready.error}`);
    const scene = await page.evaluate(() => window.pmscView.scene);
    result.scene = {kind: scene.kind, points: scene.points, dims: scene.grid.dims, model: scene.model};

    const defaults = Object.fromEntries(scene.controls.map(c => [c.name, c.value]));

    // 1. The scripted drag.
    const moves = [];
    const drag = dragPath(scene.controls, options.moves);
    // --trace: Chromium's trace of the middle 20 moves (chrome://tracing or Perfetto reads it).
    const traceFrom = Math.max(0, Math.floor(options.moves / 2) - 10);
    for (const [m, controls] of drag.entries()) {
      if (options.trace && m === traceFrom)
        await page.tracing.start({path: options.trace, categories: ['devtools.timeline', 'toplevel', 'v8',
          'blink', 'cc', 'gpu', 'viz', 'netlog', 'loading', 'disabled-by-default-devtools.timeline',
          'blink.user_timing', 'mojom', 'ipc']});
      const r = await page.evaluate(c => window.pmscView.set(c), controls);
      moves.push(r);
      if (options.trace && m === traceFrom + 19) await page.tracing.stop();
    }
    const dragSeqs = new Set(moves.map(r => r.seq));
    const recorded = (await page.evaluate(() => window.pmscView.stats.moves)).filter(m => dragSeqs.has(m.seq));
    // The images along the drag, afterwards: each hash draws the whole canvas at full size and reads
    // it back, work a drag never does, which would slow the move after it by 50-100 ms on a 2-core
    // machine. The same controls again give the same cache.
    const hashEvery = Math.max(1, Math.floor(options.moves / 10));
    const samples = [defaults];
    for (let m = hashEvery - 1; m < drag.length; m += hashEvery) samples.push(drag[m]);
    const hashes = [];
    for (const controls of samples) {
      await page.evaluate(c => window.pmscView.set(c), controls);
      hashes.push(await page.evaluate(() => window.pmscView.canvasHash()));
    }
    await page.screenshot({path: path.join(options.out, 'hit.png')});
    result.screenshots.hit = path.join(options.out, 'hit.png');
    const badChecksums = moves.filter(r => !r.checksumOk).map(r => r.seq);
    check('page cache checksum equals the server\'s for every final (and estimate)', badChecksums.length === 0, {mismatched: badChecksums});
    const unchanged = hashes.slice(1).filter((h, i) => h === hashes[i]).length;
    check('canvas changes as the light moves', unchanged === 0, {samples: hashes.length, unchanged});
    const byState = {}, convergedByState = {};
    for (const r of moves) {
      (byState[r.state] ??= []).push(r.firstImageMs);
      (convergedByState[r.state] ??= []).push(r.convergedMs);
    }
    result.latency = {
      firstImageMs: summary(moves.map(r => r.firstImageMs)),
      convergedMs: summary(moves.map(r => r.convergedMs)),
      firstImageByState: Object.fromEntries(Object.entries(byState).map(([s, v]) => [s, summary(v)])),
      // A hit's first image is shown before its check; converged is the checked image.
      convergedByState: Object.fromEntries(Object.entries(convergedByState).map(([s, v]) => [s, summary(v)])),
    };
    // The first image's latency split: the server's own time, the page's (update arrived to drawn).
    fs.writeFileSync(path.join(options.out, 'moves.json'), JSON.stringify(recorded));  // move by move
    result.latency.serverMs = summary(recorded.map(m => m.serverMs).filter(Number.isFinite));
    result.latency.pageMs = summary(recorded.map(m => m.pageMs));
    // The whole path of the hits' first images, part by part (main.js pathParts): each part's
    // p50 / p95 / max, their means beside the mean total, and the largest gap between a move's parts
    // and its total (the parts are consecutive, so it is rounding). frameWait: to the next composited
    // frame, beyond firstImageMs.
    const hitMoves = recorded.filter(m => m.state === 'hit' && m.parts);
    const names = Object.keys(hitMoves[0]?.parts ?? {});
    const mean = values => round(values.reduce((a, b) => a + b, 0) / Math.max(values.length, 1));
    result.latency.hitPathMs = {
      parts: Object.fromEntries(names.map(n => [n, summary(hitMoves.map(m => m.parts[n]))])),
      meanParts: Object.fromEntries(names.map(n => [n, mean(hitMoves.map(m => m.parts[n]))])),
      meanTotal: mean(hitMoves.map(m => m.firstImageMs)),
      largestGap: round(Math.max(0, ...hitMoves.map(m =>
        Math.abs(names.reduce((a, n) => a + m.parts[n], 0) - m.firstImageMs)))),
      frameWait: summary(hitMoves.map(m => m.frameWaitMs).filter(Number.isFinite)),
    };
    // The server's part by engine node (its final update's timing_ms: each node's thread time, the
    // engine's wall time, the encoding): the whole request's, the check after the image included.
    const timings = hitMoves.map(m => m.serverTiming).filter(t => t);
    const nodeNames = [...new Set(timings.flatMap(t => Object.keys(t)))];
    result.latency.hitServerMs = Object.fromEntries(nodeNames.map(n =>
      [n, summary(timings.map(t => t[n]).filter(Number.isFinite))]));
    check('the hits\' path parts add up to their first-image latency', hitMoves.length > 0 &&
      result.latency.hitPathMs.largestGap < 0.5, {hits: hitMoves.length, largestGap: result.latency.hitPathMs.largestGap});
    const costs = await page.evaluate(() => window.pmscView.stats.costs);
    const moveCosts = costs.filter(c => c.scale < 1);
    result.pageCostsMs = {
      apply: summary(moveCosts.map(c => c.apply)), upload: summary(moveCosts.map(c => c.upload)),
      draw: summary(moveCosts.map(c => c.draw)), scale: moveCosts[0]?.scale ?? 1,
    };

    // 2. A miss: the first far setting the server answers with state "miss".
    // A model that misses nowhere in the controls' range gets its first blend instead (reported).
    let miss = null;
    let blend = null;
    const tried = [];
    for (const candidate of missCandidates(scene)) {
      await page.evaluate(c => window.pmscView.set(c), defaults);
      const r = await page.evaluate(c => window.pmscView.set(c), candidate);
      tried.push({controls: candidate, state: r.state});
      if (r.state === 'blend' && !blend) blend = {controls: candidate, ...r};
      if (r.state === 'miss') {
        miss = {controls: candidate, ...r};
        break;
      }
    }
    result.missFound = miss !== null;
    if (!miss && tried.length) console.error(`relight: no setting missed; using the first blend: ${JSON.stringify(tried)}`);
    miss ??= blend;
    check('a light far outside training fails through (a miss, else a blend)', miss !== null, {tried});
    if (miss) {
      result.miss = {state: miss.state, controls: miss.controls, firstImageMs: round(miss.firstImageMs),
        convergedMs: round(miss.convergedMs), checks: miss.checks};
      check(`${miss.state}: estimate first, then converged, checksums equal`, miss.checksumOk && miss.checks.includes('estimate') && miss.checks.includes('final'), miss.checks);
      const missCache = await page.evaluate(() => Array.from(window.pmscView.cache()));
      // The image after the estimate's and the chunks' partial uploads equals one from the whole array.
      const partial = await page.evaluate(() => window.pmscView.canvasHash());
      const whole = await page.evaluate(() => window.pmscView.canvasHash({reupload: true}));
      check('image from partial uploads equals the image from the whole cache', partial === whole, {partial, whole});

      // The same controls by the full calculation: the converged cache must equal it.
      const full = await page.evaluate(() => window.pmscView.mode('full'));
      const fullCache = await page.evaluate(() => Array.from(window.pmscView.cache()));
      let largest = 0;
      for (let i = 0; i < fullCache.length; ++i) largest = Math.max(largest, Math.abs(fullCache[i] - missCache[i]));
      result.missVsFull = {largestDifference: largest, fullState: full.state, fullConvergedMs: round(full.convergedMs)};
      check('full mode answers with state "full"', full.state === 'full' && full.checksumOk, full);
      // A converged miss has failed through everywhere: it must be the full calculation. A converged
      // blend keeps the blended estimate outside its fail-through branches: its difference is reported.
      if (miss.state === 'miss')
        check(`converged miss equals the full calculation (largest difference <= ${options.tolerance})`, largest <= options.tolerance, {largest});
      await page.evaluate(() => window.pmscView.mode('cache'));

      // The screenshot of a miss while it converges: a nearby far light, drawing held after its estimate.
      const nearby = {...miss.controls};
      const first = scene.controls[0];
      nearby[first.name] = Math.min(first.max, Math.max(first.min, nearby[first.name] + (nearby[first.name] + 10 * first.step <= first.max ? 10 : -10) * first.step));
      await page.evaluate(c => window.pmscView.set(c), defaults);
      await page.evaluate(c => { window.__pending = window.pmscView.set(c, {holdAfterEstimate: true}); }, nearby);
      const held = await Promise.race([
        page.evaluate(() => window.pmscView.held().then(() => true)),
        page.evaluate(() => window.__pending.then(() => false)),
      ]);
      await page.screenshot({path: path.join(options.out, 'miss-estimate.png')});
      result.screenshots.missEstimate = path.join(options.out, 'miss-estimate.png');
      await page.evaluate(() => window.pmscView.release());
      const nearbyResult = await page.evaluate(() => window.__pending);
      result.missScreenshot = {controls: nearby, state: nearbyResult.state, heldAtEstimate: held};
      check('screenshot taken right after an estimate', held, result.missScreenshot);
    }

    // 3. The difference view (cache against the reference for the current controls).
    await page.evaluate(c => window.pmscView.set(c), defaults);
    const differenceMax = await page.evaluate(() => window.pmscView.difference(true));
    await page.screenshot({path: path.join(options.out, 'difference.png')});
    result.screenshots.difference = path.join(options.out, 'difference.png');
    result.differenceMax = differenceMax;
    const referenceOk = await page.evaluate(() => window.pmscView.stats.checksumErrors === 0);
    check('reference checksums equal', referenceOk);
    check('difference view drawn with a finite maximum', Number.isFinite(differenceMax), differenceMax);
    await page.evaluate(() => window.pmscView.difference(false));

    // 4. Bad input: a malformed message gets an `error` and the connection stays usable.
    const errorsBefore = await page.evaluate(() => window.pmscView.stats.errors.length);
    await page.evaluate(() => window.pmscView.sendRaw('{"type": "set", "seq": '));
    await page.waitForFunction(n => window.pmscView.stats.errors.length > n, {timeout: 10000}, errorsBefore).catch(() => {});
    const errorsAfter = await page.evaluate(() => window.pmscView.stats.errors.slice(-1));
    check('malformed message answered by an error', errorsAfter.length > 0 && (await page.evaluate(n => window.pmscView.stats.errors.length > n, errorsBefore)), errorsAfter);
    const afterBad = await page.evaluate(c => window.pmscView.set(c), dragPath(scene.controls, 7)[3]);
    check('connection usable after the malformed message', afterBad.checksumOk && afterBad.state, afterBad);

    // A second viewer is refused: an error message, then closed.
    const wsUrl = url.replace(/^http/, 'ws') + 'api/ws';
    const second = await page.evaluate(u => new Promise(resolve => {
      const messages = [];
      const ws = new WebSocket(u);
      ws.onmessage = e => messages.push(typeof e.data === 'string' ? JSON.parse(e.data) : 'binary');
      ws.onclose = () => resolve({closed: true, messages});
      setTimeout(() => resolve({closed: false, messages}), 10000);
    }), wsUrl);
    check('a second viewer gets an error and is closed', second.closed && second.messages.some(m => m.type === 'error'), second);

    // A client that disconnects mid-frame: the page leaves, a raw client asks for a miss and closes at once.
    await page.evaluate(() => window.pmscView.disconnect());
    await new Promise(r => setTimeout(r, 200));
    const abrupt = await page.evaluate((u, c) => new Promise(resolve => {
      const ws = new WebSocket(u);
      ws.onmessage = e => {
        if (typeof e.data === 'string' && JSON.parse(e.data).type === 'hello') {
          ws.send(JSON.stringify({type: 'set', seq: 1, controls: c}));
          ws.close();
          resolve(true);
        }
      };
      ws.onerror = () => resolve(false);
      setTimeout(() => resolve(false), 10000);
    }), wsUrl, miss ? miss.controls : defaults);
    check('raw client connected, sent a set and closed mid-frame', abrupt);
    await new Promise(r => setTimeout(r, 500));
    await page.goto(pageUrl);
    const again = await page.evaluate(() => window.pmscView.ready.then(r => r, e => ({error: e.message})));
    const againMove = again.error ? again : await page.evaluate(c => window.pmscView.set(c), dragPath(scene.controls, 7)[5]);
    check('server still serves a viewer after the abrupt client', !again.error && againMove.checksumOk, againMove);
    if (server) check('server process alive', serverExit === null, serverExit);
    check('no errors in the page', pageErrors.length === 0, pageErrors.slice(0, 5));
  } finally {
    await browser.close();
    if (server && serverExit === null) {
      server.process.kill('SIGTERM');
      const code = await new Promise(resolve => {
        const timer = setTimeout(() => { server.process.kill('SIGKILL'); resolve('killed'); }, 10000);
        server.process.on('exit', (c, s) => { clearTimeout(timer); resolve(c ?? s); });
      });
      result.serverExit = code;
    }
  }
  if (server) check('server exits cleanly on SIGTERM', result.serverExit === 0, result.serverExit);
  const failed = checks.filter(c => !c.ok).length;
  result.passed = checks.length - failed;
  result.failed = failed;
  console.log(JSON.stringify(result, null, 2));
  console.log(`relight: ${checks.length - failed} passed, ${failed} failed`);
  process.exit(failed ? 1 : 0);
}

main().catch(error => {
  console.error(`relight: ${error.stack || error.message}`);
  process.exit(2);
});
