// The page's side of the protocol: /api/scene, /api/geometry and the /api/ws WebSocket.

const MAGIC = 0x564d5350;  // 'P','S','M','V' as a little-endian uint32

/** Fetches the scene description and the points' dense indices (and density or normals). */
export async function loadScene() {
  const sceneResponse = await fetch('/api/scene');
  if (!sceneResponse.ok) throw new Error(`/api/scene: HTTP ${sceneResponse.status}`);
  const scene = await sceneResponse.json();
  const geometryResponse = await fetch('/api/geometry');
  if (!geometryResponse.ok) throw new Error(`/api/geometry: HTTP ${geometryResponse.status}`);
  const bytes = await geometryResponse.arrayBuffer();
  const n = scene.points;
  const perPoint = scene.kind === 'cornell' ? 3 : 1;
  const expected = n * 4 * (1 + perPoint);
  if (bytes.byteLength !== expected)
    throw new Error(`/api/geometry: ${bytes.byteLength} bytes, expected ${expected} for ${n} points`);
  const index = new Uint32Array(bytes, 0, n);
  const values = new Float32Array(bytes, n * 4, n * perPoint);
  const [nx, ny, nz] = scene.grid.dims;
  const cells = nx * ny * nz;
  for (let p = 0; p < n; ++p)
    if (index[p] >= cells) throw new Error(`/api/geometry: point ${p} has dense index ${index[p]} outside the box`);
  return {
    scene,
    index,
    density: scene.kind === 'cornell' ? null : values,
    normals: scene.kind === 'cornell' ? values : null,
  };
}

/**
 * Whole caches by HTTP: one GET /api/body/next always waits at the server, which answers it the
 * moment a body is made (its address in X-Pmsc-Body), so the bytes are on their way before the
 * WebSocket's header for them arrives. get(url) resolves with a body's bytes whichever comes first.
 */
class BodyPoller {
  constructor(onError) {
    this.onError = onError;
    this.arrived = new Map();  // url -> ArrayBuffer, not asked for yet
    this.wanted = new Map();   // url -> {resolve, reject}, not arrived yet
    this.running = false;
    this.generation = 0;  // a loop runs while its generation is the current one
    this.failing = false;
  }

  start() {
    if (this.running) return;
    this.running = true;
    this.loop(++this.generation);
  }

  /** No new request after the one in flight (the server lets that one go when another page asks). */
  stop() {
    this.running = false;
    ++this.generation;
  }

  async loop(generation) {
    while (generation === this.generation) {
      try {
        const response = await fetch('/api/body/next', {cache: 'no-store'});
        if (!response.ok) throw new Error(`/api/body/next: HTTP ${response.status}`);
        const url = response.headers.get('X-Pmsc-Body');
        if (!url) throw new Error('/api/body/next: an answer without X-Pmsc-Body');
        const bytes = await response.arrayBuffer();
        const at = performance.now();
        this.failing = false;
        const waiter = this.wanted.get(url);
        if (waiter) {
          this.wanted.delete(url);
          waiter.resolve({bytes, at});
        } else {
          this.arrived.set(url, {bytes, at});
        }
      } catch (error) {
        // A stopped loop's request ends when the server lets it go: nothing to say.
        if (generation !== this.generation) return;
        // The server went away or restarted: say so once, and ask again a little later.
        if (!this.failing) this.onError(error.message);
        this.failing = true;
        await new Promise(resolve => setTimeout(resolve, 500));
      }
    }
  }

  /**
   * A body's bytes and the time they were in hand ({bytes, at}, performance.now()); one the waiting
   * request has not brought in 5 s is asked for by its address.
   */
  get(url) {
    const body = this.arrived.get(url);
    if (body) {
      this.arrived.delete(url);
      return Promise.resolve(body);
    }
    return new Promise((resolve, reject) => {
      const timer = setTimeout(() => {
        if (!this.wanted.has(url)) return;
        this.wanted.delete(url);
        fetch(url, {cache: 'no-store'}).then(r => {
          if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
          return r.arrayBuffer();
        }).then(bytes => resolve({bytes, at: performance.now()}), reject);
      }, 5000);
      this.wanted.set(url, {
        resolve: b => { clearTimeout(timer); resolve(b); },
        reject: e => { clearTimeout(timer); reject(e); },
      });
    });
  }
}

/**
 * The WebSocket: pairs every text `update` with the binary message that follows it and hands the
 * pair to onUpdate(update, {first, count, halfs}); other messages go to onMessage.
 */
export class Connection {
  constructor({onUpdate, onMessage, onClose}) {
    this.onUpdate = onUpdate;
    this.onMessage = onMessage;
    this.onClose = onClose;
    this.pending = null;  // the text update waiting for its binary message
    this.seq = 0;
    // Updates are applied in the order they came, also when one's values come by HTTP.
    this.applied = Promise.resolve();
    this.bodies = new BodyPoller(message => this.onMessage({type: 'error', message}));
  }

  open() {
    const url = new URL('/api/ws', location.href);
    url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
    this.socket = new WebSocket(url);
    this.socket.binaryType = 'arraybuffer';
    return new Promise((resolve, reject) => {
      let hello = false;
      this.socket.onopen = () => {};
      this.socket.onerror = () => { if (!hello) reject(new Error('WebSocket /api/ws: could not connect')); };
      this.socket.onclose = event => {
        this.bodies.stop();
        if (!hello) reject(new Error(`WebSocket /api/ws closed before hello (${event.code})`));
        this.onClose?.(event);
      };
      this.socket.onmessage = event => {
        if (typeof event.data === 'string') {
          let message;
          try {
            message = JSON.parse(event.data);
          } catch {
            this.onMessage({type: 'error', message: `unparsable message from the server: ${event.data.slice(0, 80)}`});
            return;
          }
          if (message.type === 'hello' && !hello) {
            hello = true;
            // Only the page the server took as its viewer waits for bodies: a second page, which
            // the server turns away, must not take the waiting request from the first.
            this.bodies.start();
            if (message.version !== 1) reject(new Error(`server speaks protocol version ${message.version}, page speaks 1`));
            else resolve(message);
          }
          if (message.type === 'update') {
            if (this.pending) this.onMessage({type: 'error', message: 'update without its binary message'});
            // When each part of the update was in hand (performance.now()): the page's latency split.
            message.arrival = {textAt: performance.now(), binaryAt: null, bodyAt: null, applyAt: null};
            this.pending = message;
          } else {
            this.onMessage(message);
          }
          return;
        }
        this.binary(event.data);
      };
    });
  }

  binary(buffer) {
    const update = this.pending;
    this.pending = null;
    if (!update) {
      this.onMessage({type: 'error', message: 'binary message without an update'});
      return;
    }
    // A whole cache comes by HTTP (update.body; the WebSocket carried its header alone): fetch()
    // takes it several times faster than a WebSocket message in Chromium. Later updates wait for it.
    update.arrival.binaryAt = performance.now();
    const values = update.body ? this.bodies.get(update.body) : Promise.resolve({bytes: buffer, at: update.arrival.binaryAt});
    this.applied = this.applied.then(() => values).then(({bytes, at}) => {
      update.arrival.bodyAt = at;
      update.arrival.applyAt = performance.now();
      this.apply(update, bytes);
    }).catch(error => {
      this.onMessage({type: 'error', message: `update ${update.seq}: ${error.message}`});
    });
  }

  apply(update, buffer) {
    const header = new DataView(buffer, 0, 16);
    const magic = header.getUint32(0, true);
    const seq = header.getUint32(4, true);
    const first = header.getUint32(8, true);
    const count = header.getUint32(12, true);
    if (magic !== MAGIC || seq !== update.seq || buffer.byteLength !== 16 + count * 6) {
      this.onMessage({type: 'error', message: `bad binary message for seq ${update.seq} (magic ${magic.toString(16)}, seq ${seq}, ${buffer.byteLength} bytes for ${count} points)`});
      return;
    }
    this.onUpdate(update, {first, count, halfs: new Uint16Array(buffer, 16, count * 3)});
  }

  send(message) {
    this.socket.send(JSON.stringify(message));
  }

  /** Sends a `set` with the next sequence number and returns that number. */
  sendSet(controls) {
    const seq = ++this.seq;
    this.send({type: 'set', seq, controls});
    return seq;
  }

  sendReference() {
    const seq = ++this.seq;
    this.send({type: 'reference', seq});
    return seq;
  }

  sendMode(view) {
    this.send({type: 'mode', view});
  }
}
