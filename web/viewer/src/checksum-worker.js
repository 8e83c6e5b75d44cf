// Hashes the page's copies of the cache off the main thread: {id, halfs} in, {id, checksum} out.
import {fnv1a64} from './half.js';

self.onmessage = event => {
  const {id, halfs} = event.data;
  self.postMessage({id, checksum: fnv1a64(halfs)});
};
