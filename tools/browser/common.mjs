// What the browser tests share: their arguments, `cdvol serve` on a free
// port, and headless Chromium from Debian's `chromium` package.

import { spawn } from "node:child_process";
import { readFileSync } from "node:fs";
import { chromium } from "playwright-core";

// `--name value` pairs of the command line.
export function parseArgs(argv) {
  return Object.fromEntries(
    argv.reduce((acc, a, i, all) => {
      if (a.startsWith("--")) acc.push([a.slice(2), all[i + 1]]);
      return acc;
    }, []),
  );
}

// `cdvol serve FILES...` on a free port; resolves to {proc, url}. The
// last 4000 bytes of its stderr are kept in proc.stderrText.
export function startServer(cdvol, files, extra = []) {
  const proc = spawn(cdvol, ["serve", ...files, "--bind", "127.0.0.1:0", ...extra],
    { stdio: ["ignore", "ignore", "pipe"] });
  return new Promise((ok, no) => {
    let err = "";
    proc.stderr.on("data", (d) => {
      err += d;
      proc.stderrText = err.slice(-4000);
      // Wait for the whole line: a pipe may deliver it in pieces.
      const m = err.match(/listening on (http:\/\/\S+)\r?\n/);
      if (m) ok({ proc, url: m[1] });
    });
    proc.on("exit", (c) => no(new Error(`cdvol serve exited ${c}: ${err}`)));
  });
}

// Headless Chromium; launch() gives it a fresh temporary profile
// (--user-data-dir) of its own and removes it on close.
export function launch(executablePath = "/usr/bin/chromium") {
  return chromium.launch({
    executablePath,
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
}

// With `page` (a path), the browser context gets that file instead of
// the page the server embeds (`/`): the tests can then run against
// another version of page.html (e.g. `git show HEAD:src/serve/page.html`)
// without rebuilding the binary. The API stays the server's.
export async function substitutePage(context, page) {
  if (!page) return;
  const body = readFileSync(page);
  await context.route((url) => url.pathname === "/" || url.pathname === "/index.html",
    (route) => route.fulfill({ status: 200, contentType: "text/html; charset=utf-8", body }));
}
