// Hashes the page's copies of the cache off the main thread: {id, halfs} in, {id, checksum, halfs}
// out (the copy goes back to be used again).
import {wordChecksum} from './half.js';

self.onmessage = event => {
  const {id, halfs} = event.data;
  self.postMessage({id, checksum: wordChecksum(halfs), halfs}, [halfs.buffer]);
};
