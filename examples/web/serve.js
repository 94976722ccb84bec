// A static file server for the web example on 127.0.0.1:8080 (or --port N; 0 picks one): the
// page at `/`, this folder (the page's script, three.js from node_modules) under `/web/`, and the
// project folder (two folders up, or --root DIR: where `pipeline.ron` and the output are)
// everywhere else; read-only, nothing cached (a hot reload must fetch the new bytes). Prints its
// address.
const http = require('http');
const fs = require('fs');
const path = require('path');

const argument = (name, fallback) => {
  const at = process.argv.indexOf(name);
  return at >= 0 && at + 1 < process.argv.length ? process.argv[at + 1] : fallback;
};
const root = fs.realpathSync(path.resolve(argument('--root', path.join(__dirname, '..', '..'))));
const port = Number(argument('--port', process.env.PORT || 8080));
const here = fs.realpathSync(__dirname);
const types = {
  '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json',
  '.gltf': 'model/gltf+json', '.bin': 'application/octet-stream', '.png': 'image/png', '.jpg': 'image/jpeg',
  '.jpeg': 'image/jpeg', '.ktx2': 'image/ktx2', '.wasm': 'application/wasm',
};

const server = http.createServer((request, response) => {
  const url = new URL(request.url, 'http://localhost');
  const relative = url.pathname === '/' ? '/web/index.html' : decodeURIComponent(url.pathname);
  const [base, inside] = relative.startsWith('/web/') ? [here, relative.slice(4)] : [root, relative];
  let file;
  try {
    file = fs.realpathSync(path.join(base, inside));
  } catch {
    response.writeHead(404);
    return response.end('not found');
  }
  if (!file.startsWith(base + path.sep) || !fs.statSync(file).isFile() || request.method !== 'GET') {
    response.writeHead(404);
    return response.end('not found');
  }
  response.writeHead(200, {
    'Content-Type': types[path.extname(file).toLowerCase()] || 'application/octet-stream',
    'Cache-Control': 'no-store',
  });
  fs.createReadStream(file).pipe(response);
});
server.listen(port, '127.0.0.1', () => {
  console.log(`cirrus web example: http://127.0.0.1:${server.address().port}/ (files from ${root})`);
});
