// The `cdvol serve` page in a real browser (issue 18): headless Chromium
// from Debian's `chromium` package, driven through playwright-core (no
// browser download). It starts `cdvol serve FILE`, loads the page, drags
// to orbit, waits for the refined frame, takes a screenshot of the image
// and checks it against `cdvol render` of the view read from the page's
// URL. It measures input -> coarse frame and input -> full frame latency
// and frames per second while dragging; with --clients N it drags N pages
// at once and reports the server's peak RSS (VmHWM).
//
//   node view-test.mjs --cdvol target/debug/cdvol --file head.cdv [--size 1024]
//        [--mode surface] [--cache-mb 512] [--clients 1] [--drags 3]
//        [--steps 30] [--out DIR] [--json results.json]
//
// Exit status 1 when the page fails: no frame, an error shown, the
// screenshot differs from `cdvol render`, or the page's "cdvol render
// command" is not the server's for the frame shown. Timings are reported, not
// judged (they depend on the machine); docs/BENCHMARKS.md records them.

import { execFileSync } from "node:child_process";
import { mkdtempSync, readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { launch, parseArgs, startServer, substitutePage } from "./common.mjs";

const args = parseArgs(process.argv.slice(2));
const opt = {
  cdvol: resolve(args.cdvol ?? "target/debug/cdvol"),
  file: resolve(args.file ?? ""),
  size: +(args.size ?? 1024),
  mode: args.mode ?? "surface",
  extra: args.query ?? "",
  cacheMb: +(args["cache-mb"] ?? 512),
  clients: +(args.clients ?? 1),
  drags: +(args.drags ?? 3),
  steps: +(args.steps ?? 30),
  out: args.out ? resolve(args.out) : mkdtempSync(join(tmpdir(), "cdvol-browser-")),
  json: args.json,
  chromium: args["chromium"] ?? "/usr/bin/chromium",
  // Another page.html than the binary's (common.mjs, substitutePage).
  page: args.page ? resolve(args.page) : null,
};
mkdirSync(opt.out, { recursive: true });

function fail(msg) {
  console.error("view-test: FAILED: " + msg);
  process.exitCode = 1;
}

// Peak resident memory of `pid` in MiB (VmHWM).
function peakRssMib(pid) {
  const s = readFileSync(`/proc/${pid}/status`, "utf8");
  return +s.match(/VmHWM:\s+(\d+)/)[1] / 1024;
}

const median = (xs) => { const s = [...xs].sort((a, b) => a - b); return s.length ? s[Math.floor(s.length / 2)] : NaN; };
const pct = (xs, p) => { const s = [...xs].sort((a, b) => a - b); return s.length ? s[Math.min(s.length - 1, Math.floor(s.length * p))] : NaN; };

async function waitFull(page, version) {
  await page.waitForFunction((v) => {
    const l = window.__cdvol;
    return l && l.lastFull && l.lastFull.version >= v;
  }, version, { timeout: 120000 });
}

// One drag of `steps` moves 6 px apart, one every animation frame or so.
async function drag(page, box, steps, dy) {
  const x0 = box.x + box.width / 2, y0 = box.y + box.height / 2;
  await page.mouse.move(x0, y0);
  await page.mouse.down();
  const t0 = await page.evaluate(() => performance.now());
  for (let i = 1; i <= steps; i++) {
    await page.mouse.move(x0 + 6 * i, y0 + dy * i);
    await page.waitForTimeout(16);
  }
  const t1 = await page.evaluate(() => performance.now());
  await page.mouse.up();
  const version = await page.evaluate(() => window.__cdvol.version);
  await waitFull(page, version);
  return { t0, t1, version };
}

async function openPage(browser, url) {
  const ctx = await browser.newContext({ viewport: { width: 360 + opt.size, height: Math.max(900, opt.size + 40) } });
  await substitutePage(ctx, opt.page);
  const page = await ctx.newPage();
  const errors = [], consoleLines = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("console", (m) => consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on("requestfailed", (r) => consoleLines.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
  const hash = `#size=${opt.size}&mode=${opt.mode}&az=30&el=10${opt.extra ? "&" + opt.extra : ""}`;
  const t0 = Date.now();
  try {
    await page.goto(url + hash, { timeout: 120000 });
    // A fresh machine's first Chromium page can be slow (profile, fonts):
    // the same generous bound as every other wait of this script.
    await page.waitForFunction(() => window.__cdvol && window.__cdvol.ready, null, { timeout: 120000 });
    await waitFull(page, 1);
  } catch (e) {
    // Say what the page saw, not only that it timed out.
    const seen = await page.evaluate(() => ({
      log: window.__cdvol ? { ready: window.__cdvol.ready, version: window.__cdvol.version,
        frames: window.__cdvol.frames.length, lastFull: !!window.__cdvol.lastFull } : null,
      err: document.getElementById("err")?.textContent ?? null,
    })).catch((x) => "page not readable: " + x);
    await page.screenshot({ path: join(opt.out, "failed-open.png") }).catch(() => {});
    throw new Error(`opening ${url + hash} failed after ${Date.now() - t0} ms: ${e.message}\n` +
      `page state: ${JSON.stringify(seen)}\npage errors: ${JSON.stringify(errors)}\n` +
      `console: ${JSON.stringify(consoleLines.slice(-20))}`);
  }
  return { page, errors, openMs: Date.now() - t0 };
}

// Compares two PNGs (bytes) pixel by pixel inside the page's browser.
async function comparePngs(page, a, b) {
  return page.evaluate(async ([a64, b64]) => {
    const load = async (s) => {
      const bytes = Uint8Array.from(atob(s), (c) => c.charCodeAt(0));
      const bmp = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
      const c = new OffscreenCanvas(bmp.width, bmp.height);
      const g = c.getContext("2d");
      g.drawImage(bmp, 0, 0);
      return { w: bmp.width, h: bmp.height, d: g.getImageData(0, 0, bmp.width, bmp.height).data };
    };
    const [x, y] = [await load(a64), await load(b64)];
    if (x.w !== y.w || x.h !== y.h) return { sameSize: false, size: [x.w, x.h, y.w, y.h] };
    let differing = 0, maxDiff = 0, sum = 0;
    for (let i = 0; i < x.d.length; i += 4) {
      let px = 0;
      for (let k = 0; k < 3; k++) {
        const d = Math.abs(x.d[i + k] - y.d[i + k]);
        px = Math.max(px, d); sum += d;
      }
      if (px) differing++;
      maxDiff = Math.max(maxDiff, px);
    }
    return { sameSize: true, pixels: x.d.length / 4, differing, maxDiff, meanDiff: sum / (x.d.length / 4 * 3) };
  }, [a.toString("base64"), b.toString("base64")]);
}

// The `cdvol render` arguments of the view in the page's URL hash: the
// test's own reading, not the server's command line. `info` is
// /api/info: in surface and cost mode a typed iso value wins over the
// preset, and a preset counts only when it has an iso value
// (docs/SERVE.md, "The page").
function renderArgs(hash, info) {
  const q = new URLSearchParams(hash.replace(/^#/, ""));
  const size = q.get("size") ?? "512";  // the page leaves defaults out
  const mode = q.get("mode") ?? "surface";
  const a = ["--mode", mode, "--width", size, "--height", size];
  a.push("--view", q.get("view") ?? `${q.get("az") ?? 0},${q.get("el") ?? 0}`);
  const presets = info.files[+(q.get("file") ?? 0)].presets ?? info.presets;
  const preset = presets.find((p) => p.name === q.get("preset"));
  if (mode === "surface" || mode === "cost") {
    if (q.get("preset") && !q.get("iso") && preset?.iso != null) a.push("--preset", q.get("preset"));
  } else if (q.get("preset")) a.push("--preset", q.get("preset"));
  const iso = mode === "surface" || mode === "cost" || (mode === "mip" && !q.get("preset"));
  if (q.get("iso") && iso) a.push("--iso", q.get("iso"));
  for (const [k, flag] of [["frame", "--frame"], ["hit", "--hit"]]) {
    if (q.get(k)) a.push(flag, q.get(k));
  }
  if (q.get("crop")) a.push("--crop", q.get("crop"));
  if (q.get("clip")) a.push("--clip", q.get("clip"));
  if (q.get("shadows") === "1") a.push("--shadows");
  if (q.get("pan")) throw new Error("the browser test does not pan");
  return a;
}

let server = null;  // for the failure report

async function main() {
  const { proc, url } = await startServer(opt.cdvol, [opt.file], ["--cache-mb", String(opt.cacheMb)]);
  server = proc;
  const browser = await launch(opt.chromium);
  const rss = { anon: 0, file: 0 };
  const result = { file: opt.file, size: opt.size, mode: opt.mode, clients: opt.clients, cache_mb: opt.cacheMb };
  try {
    const pages = [];
    for (let c = 0; c < opt.clients; c++) pages.push(await openPage(browser, url));
    const { page } = pages[0];
    result.open_ms = pages.map((p) => p.openMs);
    const box = await page.locator("#view").boundingBox();

    // Resident memory by kind (heap vs mapped file pages), sampled.
    const sampler = setInterval(() => {
      try {
        const s = readFileSync(`/proc/${proc.pid}/status`, "utf8");
        rss.anon = Math.max(rss.anon, +s.match(/RssAnon:\s+(\d+)/)[1] / 1024);
        rss.file = Math.max(rss.file, +s.match(/RssFile:\s+(\d+)/)[1] / 1024);
      } catch (e) { /* the server has exited */ }
    }, 20);
    // Warm-up drag (the cache fills), then the measured drags; with
    // several clients they all drag at once.
    await drag(page, box, 10, 2);
    const before = await page.evaluate(() => window.__cdvol.frames.length);
    const drags = [];
    for (let d = 0; d < opt.drags; d++) {
      // Mostly sideways, up and down in turn, so the view stays away from
      // the poles.
      const all = await Promise.all(pages.map((p, i) => drag(p.page, box, opt.steps, (i + d) % 2 ? -0.5 : 0.5)));
      drags.push(all[0]);
    }
    clearInterval(sampler);
    const frames = (await page.evaluate(() => window.__cdvol.frames)).slice(before);
    const coarse = frames.filter((f) => f.kind === "coarse");
    const full = frames.filter((f) => f.kind === "full" && drags.some((d) => d.version === f.version));
    const fps = drags.map((d) => coarse.filter((f) => f.shown >= d.t0 && f.shown <= d.t1).length / ((d.t1 - d.t0) / 1000));
    Object.assign(result, {
      coarse_frames: coarse.length,
      coarse_latency_ms_median: median(coarse.map((f) => f.shown - f.input)),
      coarse_latency_ms_p90: pct(coarse.map((f) => f.shown - f.input), 0.9),
      coarse_round_trip_ms_median: median(coarse.map((f) => f.trip)),
      full_round_trip_ms_median: median(full.map((f) => f.trip)),
      coarse_render_ms_median: median(coarse.map((f) => f.render)),
      coarse_width_median: median(coarse.map((f) => f.width)),
      full_render_ms_median: median(full.map((f) => f.render)),
      full_slot_wait_ms_median: median(full.map((f) => f.wait)),
      full_latency_ms_median: median(full.map((f) => f.shown - f.input)),
      full_latency_ms_max: Math.max(...full.map((f) => f.shown - f.input)),
      drag_fps_median: median(fps),
      peak_rss_mib: peakRssMib(proc.pid),
      peak_rss_anon_mib: rss.anon,
      peak_rss_file_mib: rss.file,
    });

    // The refined frame against `cdvol render` of the URL's view.
    const hash = new URL(page.url()).hash;
    result.url_hash = hash;
    const shot = await page.locator("#view").screenshot({ path: join(opt.out, "page.png") });
    const ref = join(opt.out, "render.png");
    const info = await (await fetch(url + "api/info")).json();
    execFileSync(opt.cdvol, ["render", opt.file, "-o", ref, ...renderArgs(hash, info)], { stdio: "inherit" });
    result.compare = await comparePngs(page, shot, readFileSync(ref));
    const c = result.compare;
    if (!c.sameSize) fail(`screenshot and render differ in size: ${c.size}`);
    else if (c.maxDiff > 2 || c.differing > c.pixels * 0.001) {
      fail(`screenshot differs from cdvol render: ${c.differing} of ${c.pixels} pixels, max ${c.maxDiff}`);
    }
    // A superseded full frame whose abort lands while its body is still
    // arriving (a CI run met it with four clients): the page must take it
    // as superseded, not throw. The first request's body is held open
    // until its signal aborts, then a second change of the view aborts it.
    result.abort_mid_body = await page.evaluate(async () => {
      const real = window.fetch;
      let headers;
      const arrived = new Promise((ok) => { headers = ok; });
      let held = false;
      window.fetch = async (url, init) => {
        const r = await real(url, init);
        if (held || !init?.signal) return r;
        held = true;
        r.body?.cancel();
        const signal = init.signal;
        const body = new ReadableStream({
          start(c) {
            signal.addEventListener("abort", () => c.error(new DOMException("aborted", "AbortError")));
            headers();
          },
        });
        return new Response(body, { status: r.status, headers: r.headers });
      };
      // Every error text the page shows meanwhile (the next frame clears it).
      const shownErrors = [];
      const watch = new MutationObserver(() => {
        const t = document.getElementById("err").textContent;
        if (t) shownErrors.push(t);
      });
      watch.observe(document.getElementById("err"), { childList: true, characterData: true, subtree: true });
      try {
        changed(true);
        await arrived;
        changed(true);
        const v = window.__cdvol.version;
        while (!(window.__cdvol.lastFull && window.__cdvol.lastFull.version >= v)) {
          await new Promise((ok) => setTimeout(ok, 20));
        }
        // Nothing may be shown in between: an aborted frame is no error.
        return { held, error_shown: shownErrors.join("; "),
                 shown_version: window.__cdvol.lastFull.version };
      } finally {
        watch.disconnect();
        window.fetch = real;
      }
    });
    // The page's command is the server's for the full frame shown.
    result.command = await page.evaluate(() => ({
      page: document.getElementById("cmd").textContent, server: window.__cdvol.lastFull.stats.command }));
    if (result.command.page !== result.command.server) {
      fail(`the page's command "${result.command.page}" is not the server's "${result.command.server}"`);
    }
    if (!result.abort_mid_body.held) fail("the mid-body abort was not exercised");
    if (result.abort_mid_body.error_shown) fail("the aborted frame showed: " + result.abort_mid_body.error_shown);
    for (const p of pages) if (p.errors.length) fail("page errors: " + p.errors.join("; "));
    const shown = await page.evaluate(() => document.getElementById("err").textContent);
    if (shown) fail("the page shows an error: " + shown);
    if (!coarse.length) fail("no coarse frame while dragging");
  } finally {
    await browser.close();
    proc.kill("SIGTERM");
  }
  console.log(JSON.stringify(result, null, 2));
  if (opt.json) writeFileSync(opt.json, JSON.stringify(result, null, 2) + "\n");
  console.log(process.exitCode ? "view-test: 0 passed, 1 failed" : "view-test: 1 passed, 0 failed");
}

main().catch((e) => {
  console.error(e);
  if (server) console.error("cdvol serve stderr (last 4000 bytes):\n" + (server.stderrText ?? ""));
  console.log("view-test: 0 passed, 1 failed");
  process.exit(1);
});
