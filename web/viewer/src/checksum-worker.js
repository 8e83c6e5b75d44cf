// Hashes the page's copies of the cache off the main thread: {id, halfs} in, {id, checksum} out.
import {wordChecksum} from './half.js';

self.onmessage = event => {
  const {id, halfs} = event.data;
  self.postMessage({id, checksum: wordChecksum(halfs)});
};
