// pmsc view: the page. Loads the scene, keeps the cache (N x 3 halfs) up to date from the server's
// updates, draws it, and measures the time from a light move to the image drawn.

import * as THREE from 'three';
import {OrbitControls} from 'three/addons/controls/OrbitControls.js';
import {Connection, loadScene} from './net.js';
import {HALF_TO_FLOAT, floatToHalf, fnv1a64} from './half.js';
import {Panel} from './panel.js';
import {VolumeView} from './volume.js';
import {CornellView} from './cornell.js';

const params = new URLSearchParams(location.search);
const [width, height] = (params.get('size') || '480x360').split('x').map(Number);
const stepVoxels = Number(params.get('step') || 1);
const interactiveScale = Number(params.get('interactive') || 0.4);
const interactiveStep = Number(params.get('istep') || 1.5);
const alwaysSmooth = params.get('smooth') === '1';  // trilinear density while moving too

const stats = {
  moves: [],           // {seq, state, firstImageMs, convergedMs, inputMs, pageMs, serverMs, parts, frameWaitMs, serverTiming}: one per answered `set`
  costs: [],           // {apply, upload, draw} ms and the resolution scale: one per image drawn
  checksumsVerified: 0,
  checksumErrors: 0,
  errors: [],          // the server's `error` messages and the page's own
};

function toFloats(halfs) {
  const out = new Float32Array(halfs.length);
  for (let n = 0; n < halfs.length; ++n) out[n] = HALF_TO_FLOAT[halfs[n]];
  return out;
}

/**
 * The direction out of the room through its open side: the face of the quads' bounding box on which
 * no quad lies (within 2% of the box), -z where every face has one.
 */
function openSide(quads) {
  const box = new THREE.Box3();
  for (const quad of quads) for (const corner of quad.corners) box.expandByPoint(new THREE.Vector3(...corner));
  const size = box.getSize(new THREE.Vector3());
  const tolerance = 0.02 * Math.max(size.x, size.y, size.z);
  for (const axis of ['z', 'x', 'y']) {
    for (const [end, sign] of [['min', -1], ['max', 1]]) {
      const plane = box[end][axis];
      const covered = quads.some(q => q.corners.every(c => Math.abs(c['xyz'.indexOf(axis)] - plane) <= tolerance));
      if (!covered) return new THREE.Vector3().setComponent('xyz'.indexOf(axis), sign);
    }
  }
  return new THREE.Vector3(0, 0, -1);
}

async function start() {
  const info = await loadScene();
  const {scene} = info;
  const n = scene.points;
  const reference = new Uint16Array(n * 3);

  const canvas = document.getElementById('view');
  const renderer = new THREE.WebGLRenderer({canvas, antialias: false, powerPreference: 'high-performance'});
  renderer.setPixelRatio(1);
  renderer.setSize(width, height, true);
  const gl = renderer.getContext();

  const view = scene.kind === 'cornell' ? new CornellView(renderer, info) : new VolumeView(renderer, info);
  const cache = view.cache.cache;  // N x 3 halfs: also the data of the texture the shaders read
  view.setStep(stepVoxels);
  const world = new THREE.Scene();
  world.add(view.object);

  const target = new THREE.Vector3(...scene.camera.target);
  const up = new THREE.Vector3(...(scene.camera.up || [0, 1, 0]));
  const toward = scene.kind === 'cornell' ? openSide(scene.quads) : new THREE.Vector3(1, 0.35, 0.45);
  const camera = new THREE.PerspectiveCamera(40, width / height, scene.camera.distance / 100, scene.camera.distance * 20);
  camera.up.copy(up);
  camera.position.copy(target).addScaledVector(toward.normalize(), scene.camera.distance);
  camera.lookAt(target);

  // The light: a marker, and a line from the camera target to it.
  const marker = new THREE.Mesh(new THREE.SphereGeometry(1, 16, 12), new THREE.MeshBasicMaterial({color: 0xffd040}));
  const lineGeometry = new THREE.BufferGeometry().setFromPoints([target, target]);
  const line = new THREE.Line(lineGeometry, new THREE.LineBasicMaterial({color: 0x806820}));
  world.add(marker, line);
  const placeLight = light => {
    marker.position.set(...light.position);
    // Its size: the light's radius, kept between 0.5% and 3% of the camera's distance.
    const d = scene.camera.distance;
    marker.scale.setScalar(Math.min(Math.max(light.radius, d / 200), d / 33));
    lineGeometry.setFromPoints([target, marker.position]);
    camera.far = Math.max(camera.far, 2 * camera.position.distanceTo(marker.position));
    camera.updateProjectionMatrix();
  };
  placeLight(scene.light);

  const orbit = new OrbitControls(camera, canvas);
  orbit.target.copy(target);
  orbit.update();

  // Drawing. Updates only mark the image dirty; one draw serves every update that arrived before it.
  let drawTimer = null;      // a draw scheduled for the next task
  let held = false;         // the test's screenshot of the estimate: no drawing until release()
  let holdAfterEstimate = false;
  const drawnEvents = [];   // {frame, kind: 'first'|'converged'} waiting for the next draw
  const pixel = new Uint8Array(4);

  // Light moves draw at the reduced `interactive` resolution (SwiftShader pays per pixel); the full
  // resolution follows once nothing new has arrived for `refineMs`.
  let scale = 1;
  let refineTimer = null;
  let statsTimer = null;  // the panel's figures after checksums verified between images
  const refineMs = Number(params.get('refine') || 250);
  function setScale(s) {
    if (s === scale) return;
    scale = s;
    view.setStep(s < 1 ? interactiveStep : stepVoxels, alwaysSmooth || s >= 1);
    renderer.setPixelRatio(s);
    renderer.setSize(width, height, true);
  }

  function drawNow(s = 1) {
    setScale(s);
    const t0 = performance.now();
    view.cache.upload();  // the cache's changed rows
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // waits for it
    const t1 = performance.now();
    renderer.render(world, camera);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // waits for the draw to finish
    const t2 = performance.now();
    return {t0, t1, t2};
  }

  function draw() {
    clearTimeout(drawTimer);
    drawTimer = null;
    if (held) return;
    const moving = (drawnEvents.length > 0 || orbiting) && interactiveScale < 1;
    const {t0, t1, t2} = drawNow(moving ? interactiveScale : 1);
    stats.costs.push({apply: applyMs, upload: t1 - t0, draw: t2 - t1, scale});
    applyMs = 0;
    clearTimeout(statsTimer);
    statsTimer = null;
    clearTimeout(refineTimer);
    if (moving) refineTimer = setTimeout(() => { if (!held) drawNow(1); }, refineMs);
    const events = drawnEvents.splice(0);
    for (const event of events) drawn(event, {t0, t1, t2});
    panel.showStats(stats);
    if (events.some(e => e.kind === 'first' && e.phase === 'estimate') && holdAfterEstimate) {
      holdAfterEstimate = false;
      held = true;
      heldResolve?.();
    }
    verifyQueued();
  }

  function scheduleDraw() {
    drawTimer ??= setTimeout(draw, 0);
  }

  let orbiting = false;
  orbit.addEventListener('start', () => { orbiting = true; });
  orbit.addEventListener('end', () => { orbiting = false; scheduleDraw(); });
  orbit.addEventListener('change', scheduleDraw);

  // Frames: one per `set` (target cache) or `reference` (target reference).
  const frames = new Map();
  let outstanding = null;   // the cache frame whose first image is not drawn yet
  let unsent = null;        // {inputAt, waiters}: controls changed while a frame was outstanding
  let mode = 'cache';
  let difference = false;
  let lastUpdate = null;

  function sendControls(inputAt, waiters) {
    const seq = connection.sendSet({...panel.values});
    console.timeStamp(`pmsc set ${seq}`);  // a mark in a Chromium trace (relight.mjs --trace), nothing else
    const frame = {seq, target: 'cache', sentAt: performance.now(), inputAt, waiters, state: null,
      firstAt: null, convergedAt: null, checks: [], done: false};
    frames.set(seq, frame);
    outstanding = frame;
    return frame;
  }

  /**
   * One first image's path, in ms, consecutive so that they add up to t2 - sentAt:
   * request (the `set` sent to the server reading it: the page's and the browser's way out, the
   * WebSocket, the server's I/O thread; by the system clock, which the page and a server on the same
   * machine share), server (its own time, request read to update sent), reply (to the update's text
   * message in hand: the way back and the page's event loop), binary (text to the binary message
   * that pairs with it), body (to the whole cache in hand, by HTTP: after the binary message when it
   * had not come first), queue (to the earlier updates applied), dispatch (to the page's update
   * handler), apply (the values into the cache's array, the canvas set to the moving resolution),
   * upload (the changed rows to the GPU) and draw (the scene rendered).
   */
  function pathParts(sentAt, event, t0, t1, t2) {
    const a = event.arrival;
    if (!a) return null;
    const toText = a.textAt - sentAt;
    const server = Number.isFinite(event.serverMs) ? Math.min(event.serverMs, toText) : 0;
    // A server on another machine has another clock: its reading, clamped, splits the rest only
    // as well as the two clocks agree.
    const out = Number.isFinite(event.receivedUnixMs) ? event.receivedUnixMs - (performance.timeOrigin + sentAt) : 0;
    const request = Math.min(Math.max(out, 0), toText - server);
    const bodyAt = Math.max(a.binaryAt, a.bodyAt);
    return {request, server, reply: toText - server - request, binary: a.binaryAt - a.textAt,
      body: bodyAt - a.binaryAt, queue: a.applyAt - bodyAt, dispatch: event.arrivedAt - a.applyAt,
      apply: t0 - event.arrivedAt, upload: t1 - t0, draw: t2 - t1};
  }

  function requestSet(waiter) {
    const now = performance.now();
    if (!outstanding) {
      sendControls(now, waiter ? [waiter] : []);
    } else {
      unsent ??= {inputAt: now, waiters: []};
      if (waiter) unsent.waiters.push(waiter);
    }
  }

  function drawn(event, {t0, t1, t2}) {
    const frame = event.frame;
    const at = t2;
    if (event.kind === 'first' && frame.firstAt === null) {
      frame.firstAt = at;
      console.timeStamp(`pmsc first image ${frame.seq}`);
      if (frame.target === 'cache') {
        // pageMs: from the first image's update arriving to it drawn; serverMs: the server's own
        // time for it (request received to update sent); parts: the whole path, split so that the
        // parts add up to firstImageMs.
        frame.move = {seq: frame.seq, state: frame.state, firstImageMs: at - frame.sentAt, convergedMs: null,
          inputMs: at - frame.inputAt, pageMs: at - event.arrivedAt, serverMs: event.serverMs ?? null,
          parts: pathParts(frame.sentAt, event, t0, t1, t2), frameWaitMs: null,
          serverTiming: event.phase === 'final' ? event.serverTiming : null};
        stats.moves.push(frame.move);
        const move = frame.move;
        // The frame wait: from the image drawn into the canvas to the next frame the browser
        // composites (its requestAnimationFrame callback); what a user waits beyond firstImageMs.
        requestAnimationFrame(() => { move.frameWaitMs = performance.now() - t2; });
      }
      if (frame.target === 'cache' && outstanding === frame) {
        outstanding = null;
        if (unsent) {
          const {inputAt, waiters} = unsent;
          unsent = null;
          sendControls(inputAt, waiters);
        }
      }
    }
    if (event.kind === 'converged') {
      frame.convergedAt = at;
      if (frame.target === 'cache' && frame.move) {
        const move = frame.move;
        move.convergedMs = at - frame.sentAt;
        // A hit's first image is its estimate, shown before its check: the state and the server's
        // timing of the whole request are the final's (a hit the check refused converges a blend).
        move.state = frame.state;
        move.serverTiming ??= event.serverTiming;
        panel.showConverged(frame.state === 'hit'
          ? `hit: checked in ${move.convergedMs.toFixed(1)} ms (first image ${move.firstImageMs.toFixed(1)} ms)`
          : `converged in ${move.convergedMs.toFixed(1)} ms (first image ${move.firstImageMs.toFixed(1)} ms)`);
      }
    }
  }

  // Checksums: the array is copied when an estimate or final is applied and hashed by a worker once
  // the image is drawn, so the hash (~20 ms for 254k points) never delays an image or a message.
  // A final that brings no values (a hit whose check stood) leaves the array as its estimate's
  // snapshot had it: it takes that snapshot's hash instead of copying and hashing it again.
  const checksumWorker = new Worker(new URL('./checksum-worker.js', import.meta.url), {type: 'module'});
  const checksumPending = new Map();
  let checksumIds = 0;
  // Snapshots come back from the worker and are used again: a fresh 1.5 MB array costs the page
  // about 4 ms of page faults on a 2-core virtual machine, a copy into one already touched 0.3 ms.
  const snapshots = [];
  checksumWorker.onmessage = event => {
    const item = checksumPending.get(event.data.id);
    checksumPending.delete(event.data.id);
    if (snapshots.length < 4) snapshots.push(event.data.halfs);  // cache and reference: both N x 3
    verified(item, event.data.checksum);
  };
  // Per array, a count of the updates that changed it, and the last snapshot taken of it.
  const changes = new Map([[cache, 0], [reference, 0]]);
  const lastSnapshot = new Map();
  function verification(frame, array, expected, phase) {
    const item = {frame, expected, phase};
    item.actual = new Promise(resolve => { item.resolveActual = resolve; });
    const last = lastSnapshot.get(array);
    if (last && last.changes === changes.get(array)) {
      item.sameAs = last.item;
    } else {
      item.snapshot = snapshots.pop() ?? new Uint16Array(array.length);
      item.snapshot.set(array);
      lastSnapshot.set(array, {item, changes: changes.get(array)});
    }
    return item;
  }
  checksumWorker.onerror = event => panel.showError(`checksum worker: ${event.message}`);
  const toVerify = [];
  function verifyQueued() {
    // A cache frame's final waits for its image: finish() reports the time it was drawn.
    const waiting = toVerify.filter(v => v.phase === 'final' && v.frame.target === 'cache' && v.frame.convergedAt === null);
    const ready = toVerify.filter(v => !waiting.includes(v));
    toVerify.length = 0;
    toVerify.push(...waiting);
    for (const item of ready) {
      if (item.sameAs) {
        item.sameAs.actual.then(actual => verified(item, actual));
        continue;
      }
      const id = ++checksumIds;
      checksumPending.set(id, item);
      checksumWorker.postMessage({id, halfs: item.snapshot}, [item.snapshot.buffer]);
    }
  }

  function verified(item, actual) {
    const {frame, expected, phase} = item;
    item.resolveActual(actual);
    const ok = actual === expected;
    frame.checks.push({phase, ok});
    if (ok) stats.checksumsVerified++;
    else {
      stats.checksumErrors++;
      const text = `checksum mismatch: seq ${frame.seq} ${frame.target} ${phase}: page ${actual}, server ${expected}`;
      stats.errors.push(text);
      panel.showError(text);
    }
    if (phase === 'final') finish(frame);
    // The count shows with the next image, or after a pause: a panel change on its own costs the
    // browser a whole composited frame (up to 15 ms of CPU on the 2-core machine where SwiftShader
    // composites), which would fall into the next move's time.
    statsTimer ??= setTimeout(() => {
      statsTimer = null;
      panel.showStats(stats);
    }, refineMs);
  }

  function finish(frame) {
    frame.done = true;
    frames.delete(frame.seq);
    const result = {seq: frame.seq, target: frame.target, state: frame.state,
      firstImageMs: frame.firstAt === null ? null : frame.firstAt - frame.sentAt,
      convergedMs: frame.convergedAt === null ? null : frame.convergedAt - frame.sentAt,
      checksumOk: frame.checks.every(c => c.ok), checks: frame.checks.map(c => c.phase)};
    if (frame.target === 'reference' && difference) showDifference();
    for (const resolve of frame.waiters.splice(0)) resolve(result);
  }

  let heldUpdate = null;
  function showUpdate(update) {
    panel.showUpdate(update);
    if (update.phase !== 'final') panel.showConverged(`converging: ${update.points_done} / ${update.points_total} points`);
  }

  let applyMs = 0;  // time spent applying updates since the last draw
  function onUpdate(update, binary) {
    const start = performance.now();
    const next = applyUpdate(update, binary, start);
    applyMs += performance.now() - start;
    if (next === 'draw') draw();
    else if (next === 'schedule') scheduleDraw();
  }

  function applyUpdate(update, {first, count, halfs}, start) {
    const frame = frames.get(update.seq);
    if (!frame) {
      stats.errors.push(`update for unknown seq ${update.seq}`);
      return null;
    }
    const array = update.target === 'reference' ? reference : cache;
    array.set(halfs, first * 3);
    if (count > 0) changes.set(array, changes.get(array) + 1);
    frame.state = update.state;
    lastUpdate = update;
    if (update.phase === 'estimate' || update.phase === 'final')
      toVerify.push(verification(frame, array, update.checksum, update.phase));
    if (update.target === 'reference' && update.phase === 'final') {
      frame.convergedAt = performance.now();
      verifyQueued();
    }
    if (update.target === 'cache') {
      // The server answers only the newest request: older frames are over; their callers get this one.
      for (const [seq, old] of frames) {
        if (seq < update.seq && old.target === 'cache' && !old.done) {
          old.done = true;
          frames.delete(seq);
          frame.waiters.push(...old.waiters.splice(0));
          if (outstanding === old) outstanding = null;
        }
      }
      if (update.phase === 'final' && count === 0 && frame.firstAt !== null && !held && drawTimer === null &&
          drawnEvents.length === 0) {
        // A final without values (a hit whose check stood) for the light already on screen: that
        // image is its converged one. Drawing it again would cost a whole ray march (in SwiftShader,
        // CPU the next light's message and image wait for) for the same pixels.
        showUpdate(update);
        const now = performance.now();
        drawn({frame, kind: 'converged', serverTiming: update.timing_ms}, {t0: now, t1: now, t2: now});
        verifyQueued();
        return null;
      }
      if (!difference) view.cache.touched(first, count);
      if (update.phase === 'estimate' || update.phase === 'final' || update.phase === 'chunk')
        drawnEvents.push({frame, kind: 'first', phase: update.phase, arrivedAt: start,
          serverMs: update.timing_ms?.since_request, receivedUnixMs: update.received_unix_ms,
          serverTiming: update.timing_ms, arrival: update.arrival});
      if (update.phase === 'final') drawnEvents.push({frame, kind: 'converged', serverTiming: update.timing_ms});
      placeLight(update.light);
      if (held) heldUpdate = update;  // the panel stays with the held image too
      else showUpdate(update);
      // A light's first image is drawn at once; later chunks share a draw (the next task).
      // (The test's screenshot of an estimate relies on it: drawn before any chunk lands, then held.)
      return frame.firstAt === null && !held ? 'draw' : 'schedule';
    }
    return null;
  }

  function onMessage(message) {
    if (message.type === 'error') {
      stats.errors.push(message.message);
      panel.showError(`server: ${message.message}`);
    }
  }

  // The difference view: |cache - reference|, largest channel, scaled to its maximum.
  let differenceMax = null;
  function showDifference() {
    const a = cache;
    const b = reference;
    const diff = new Float32Array(n);
    let max = 0;
    for (let p = 0; p < n; ++p) {
      let d = 0;
      for (let c = 0; c < 3; ++c) d = Math.max(d, Math.abs(HALF_TO_FLOAT[a[3 * p + c]] - HALF_TO_FLOAT[b[3 * p + c]]));
      diff[p] = d;
      if (d > max) max = d;
    }
    const halfs = new Uint16Array(n * 3);
    for (let p = 0; p < n; ++p) halfs[3 * p] = halfs[3 * p + 1] = halfs[3 * p + 2] = floatToHalf(diff[p]);
    view.cache.show(halfs);
    view.showDifference(true, max);
    differenceMax = max;
    panel.showDifference(`max ${max.toPrecision(4)} (heat: black 0 → white max)`);
    showCaption();
    draw();
  }

  const referenceRequest = () => new Promise(resolve => {
    const seq = connection.sendReference();
    frames.set(seq, {seq, target: 'reference', sentAt: performance.now(), waiters: [resolve], state: null,
      firstAt: null, convergedAt: null, checks: [], done: false});
  });

  const panel = new Panel(document.getElementById('panel'), scene.controls, {
    onControl: () => requestSet(null),
    onExposure: (exposure, gamma) => { view.setExposure(exposure, gamma); scheduleDraw(); },
    onFull: on => setMode(on ? 'full' : 'cache'),
    onDifference: on => toggleDifference(on),
  });

  async function toggleDifference(on) {
    difference = on;
    if (on) {
      await referenceRequest();  // its final shows the difference
    } else {
      view.showDifference(false, 0);
      view.cache.show(null);
      panel.showDifference('–');
      differenceMax = null;
      showCaption();
      draw();
    }
  }

  const caption = document.getElementById('caption');
  function showCaption() {
    const what = scene.kind === 'cornell' ? 'indirect light' : 'in-scattered light';
    caption.textContent = difference && differenceMax !== null
      ? `difference |cache − reference|: black 0 → white ${differenceMax.toPrecision(3)}`
      : `${what} (${mode === 'full' ? 'full calculation' : 'cache'})`;
  }
  showCaption();

  function setMode(view) {
    mode = view;
    showCaption();
    panel.full.checked = view === 'full';
    connection.sendMode(view);
    return new Promise(resolve => requestSet(resolve));
  }

  window.addEventListener('keydown', event => {
    const names = scene.controls.map(c => c.name);
    const step = {ArrowLeft: [0, -1], ArrowRight: [0, 1], ArrowDown: [1, -1], ArrowUp: [1, 1]}[event.key];
    if (!step || event.target instanceof HTMLInputElement || names[step[0]] === undefined) return;
    const control = scene.controls[step[0]];
    panel.setControl(control.name, panel.values[control.name] + step[1] * 4 * control.step);
    requestSet(null);
    event.preventDefault();
  });

  const connection = new Connection({onUpdate, onMessage, onClose: () => panel.showError('connection to the server closed')});
  window.addEventListener('pagehide', () => connection.socket?.close());
  await connection.open();
  document.body.classList.add('connected');

  const api = {
    stats,
    scene,
    /** Sets controls (only those given) and resolves when that light's converged image is drawn. */
    set(controls, options = {}) {
      for (const [name, value] of Object.entries(controls)) panel.setControl(name, value);
      if (options.holdAfterEstimate) holdAfterEstimate = true;
      return new Promise(resolve => requestSet(resolve));
    },
    /** Resolves once a held estimate image is on screen (after set(..., {holdAfterEstimate: true})). */
    held: () => new Promise(resolve => { if (held) resolve(); else heldResolve = resolve; }),
    release() {
      held = false;
      heldResolve = null;
      if (heldUpdate) showUpdate(heldUpdate);
      heldUpdate = null;
      scheduleDraw();
    },
    cache: () => toFloats(cache),
    reference: () => toFloats(reference),
    mode: setMode,
    requestReference: referenceRequest,
    /** The difference view on (resolves with the largest difference once drawn) or off. */
    async difference(on) {
      panel.difference.checked = on;
      await toggleDifference(on);
      return on ? differenceMax : null;
    },
    lastUpdate: () => lastUpdate,
    /** Sends a text message as it is (the tests' malformed input). */
    sendRaw: text => connection.socket.send(text),
    /** Closes the WebSocket (the server then takes another viewer). */
    disconnect() {
      connection.onClose = null;
      connection.socket.close();
    },
    currentMode: () => mode,
    /** Times k draws of the current image at a resolution scale and step (voxels): the GPU's share. */
    timeDraw(k = 5, s = 1, step = stepVoxels, upload = false) {
      const times = [];
      for (let i = 0; i < k; ++i) {
        if (upload) view.cache.touched(0, n);  // as a hit does: the whole cache again
        setScale(s);
        view.setStep(step, alwaysSmooth || s >= 1);
        const {t0, t1, t2} = drawNow(s);
        times.push(upload ? {upload: t1 - t0, draw: t2 - t1} : t2 - t1);
      }
      drawNow(1);
      return times;
    },
    /**
     * FNV-1a 64 of the scene's pixels (drawn afresh at full size, without the light's marker);
     * reupload: after uploading the whole cache again.
     */
    canvasHash({reupload = false} = {}) {
      if (reupload) view.cache.touched(0, n);  // the whole array again: partial uploads must match it
      marker.visible = line.visible = false;
      drawNow();
      const w = gl.drawingBufferWidth;
      const h = gl.drawingBufferHeight;
      const pixels = new Uint8Array(w * h * 4);
      gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
      marker.visible = line.visible = true;
      drawNow();
      return fnv1a64(pixels);
    },
  };
  let heldResolve = null;
  window.pmscView.stats = stats;
  Object.assign(window.pmscView, api);

  // The first image: the scene's default controls.
  return api.set({});
}

let readyResolve;
let readyReject;
window.pmscView = {ready: new Promise((resolve, reject) => { readyResolve = resolve; readyReject = reject; })};
start().then(readyResolve, error => {
  const message = document.getElementById('fatal');
  message.textContent = `pmsc view: ${error.message}`;
  message.classList.add('visible');
  readyReject(error);
});
