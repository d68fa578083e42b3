// A tiny static server for the page: web/ at /, the repository's models/ at /models/,
// with the cross-origin isolation headers that ort-web's threads need.
// Usage: node web/serve.mjs [port]   (or PORT=...; default 8080; 0 picks a free port)
import { createServer } from 'node:http';
import { createReadStream, promises as fs } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const webRoot = path.dirname(fileURLToPath(import.meta.url));
const modelsRoot = path.resolve(webRoot, '..', 'models');
const ortRoot = path.join(webRoot, 'node_modules', 'onnxruntime-web', 'dist');

const MIME = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.json': 'application/json',
  '.wasm': 'application/wasm',
  '.onnx': 'application/octet-stream',
  '.wav': 'audio/wav',
  '.png': 'image/png',
  '.svg': 'image/svg+xml',
  '.map': 'application/json',
  '.md': 'text/plain; charset=utf-8',
};

// The file a URL path names, or null when it lies outside the served folders.
function resolve(urlPath) {
  let rel;
  try {
    rel = decodeURIComponent(urlPath);
  } catch {
    return null;
  }
  let root = webRoot;
  if (rel.startsWith('/models/')) {
    root = modelsRoot;
    rel = rel.slice('/models'.length);
  } else if (rel.startsWith('/ort/')) {
    root = ortRoot;
    rel = rel.slice('/ort'.length);
  } else if (rel === '/' || rel === '') {
    rel = '/index.html';
  } else if (rel.startsWith('/node_modules/')) {
    return null;
  }
  const file = path.resolve(root, '.' + path.posix.normalize(rel));
  return file === root || file.startsWith(root + path.sep) ? file : null;
}

export function startServer(port = 8080, host = '127.0.0.1') {
  const server = createServer(async (req, res) => {
    const headers = {
      'Cross-Origin-Opener-Policy': 'same-origin',
      'Cross-Origin-Embedder-Policy': 'require-corp',
      'Cross-Origin-Resource-Policy': 'same-origin',
      'Cache-Control': 'no-cache',
    };
    const url = new URL(req.url, 'http://localhost');
    const file = resolve(url.pathname);
    if (req.method !== 'GET' && req.method !== 'HEAD') {
      res.writeHead(405, { ...headers, 'Content-Type': 'text/plain' });
      res.end('method not allowed\n');
      return;
    }
    let stat = null;
    if (file) {
      try {
        stat = await fs.stat(file);
      } catch {
        stat = null;
      }
    }
    if (!stat || !stat.isFile()) {
      res.writeHead(404, { ...headers, 'Content-Type': 'text/plain' });
      res.end(`not found: ${url.pathname}\n`);
      return;
    }
    const type = MIME[path.extname(file).toLowerCase()] || 'application/octet-stream';
    res.writeHead(200, { ...headers, 'Content-Type': type, 'Content-Length': stat.size });
    if (req.method === 'HEAD') {
      res.end();
      return;
    }
    createReadStream(file).pipe(res);
  });
  return new Promise((ok, fail) => {
    server.once('error', fail);
    server.listen(port, host, () => ok(server));
  });
}

if (process.argv[1] && path.resolve(process.argv[1]) === fileURLToPath(import.meta.url)) {
  const port = Number(process.argv[2] ?? process.env.PORT ?? 8080);
  if (!Number.isInteger(port) || port < 0 || port > 65535) {
    console.error(`serve: not a port: ${process.argv[2] ?? process.env.PORT}`);
    process.exit(2);
  }
  startServer(port)
    .then((s) => console.log(`serving ${webRoot} on http://127.0.0.1:${s.address().port}/`))
    .catch((e) => {
      console.error(`serve: ${e.message}`);
      process.exit(1);
    });
}
