// Screenshot of the browser view for the README (docs/src/images/view.png): with `danced demo
// --view` running, `node --experimental-websocket scripts/view_screenshot.mjs 9000 OUT.png`.
// Drives headless Chromium over the DevTools protocol: open the view, wait in real time, screenshot.
import { spawn } from 'node:child_process';
import { writeFileSync } from 'node:fs';
const chrome = spawn('chromium-headless-shell', ['--no-sandbox', '--disable-dev-shm-usage',
  '--enable-unsafe-swiftshader', '--window-size=900,600', '--remote-debugging-port=9333', 'about:blank']);
await new Promise(r => setTimeout(r, 2000));
const list = await (await fetch('http://127.0.0.1:9333/json')).json();
const page = list.find(t => t.type === 'page');
const ws = new WebSocket(page.webSocketDebuggerUrl);
let id = 0; const pending = new Map();
ws.onmessage = e => { const m = JSON.parse(e.data); if (pending.has(m.id)) { pending.get(m.id)(m); pending.delete(m.id); } };
await new Promise(r => ws.onopen = r);
const call = (method, params = {}) => new Promise(r => { const i = ++id; pending.set(i, r); ws.send(JSON.stringify({ id: i, method, params })); });
await call('Page.navigate', { url: 'http://127.0.0.1:8080/' });
await new Promise(r => setTimeout(r, Number(process.argv[2] || 6000)));
const shot = await call('Page.captureScreenshot', { format: 'png' });
writeFileSync(process.argv[3] || '/tmp/shot/view.png', Buffer.from(shot.result.data, 'base64'));
ws.close(); chrome.kill();
