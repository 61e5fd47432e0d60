// The `cdvol serve` page's handling of refusals, its command line and its
// preset menu (issue 51, item 10), in headless Chromium (Debian's
// package, driven by playwright-core). It serves FILE and FILE2 (FILE
// again by default: two files to switch between) and checks, each on its
// own:
//
//   error-over-image   a refused request (an iso value outside the file's
//                      envelope) shows the server's message over the
//                      image, in readable type, on top of it
//   image-stays        the last good image stays under it (not black)
//   bad-iso-marked     the refused iso value is marked on its input, with
//                      the server's message next to it
//   next-change-renders changing another control (hit method) renders: the
//                      refused value does not stick; the message goes
//   abc-refused-then-recovers  iso "abc" is sent, refused and marked, and the
//                      next change of another control (shadows) renders
//   command-before-frame  with every image request held, the command
//                      ("cdvol render command") changes with the controls
//   command-is-servers  after full frames (an orbit, a pan), the page's
//                      command is the one the server reports
//   preset-menu-file-0, preset-menu-file-1  the preset menu lists only
//                      the file's presets (`files[i].presets` of /api/info)
//   file-switch-preset  selecting file 1 selects its `look`, else keeps the
//                      preset only if file 1 offers it
//   zoom-from-placed-frame  the first wheel notch zooms 10 % out from the
//                      frame the server placed (`frame_mm` of its stats)
//   surface-preset-without-iso  surface mode with a preset that has no iso
//                      value (an MR composite preset on a server before
//                      issue 51) renders
//
// FILE must be prepared above iso 200 (200 is the refused value). While
// /api/info gives no `files[i].presets` (a server from before issue 51),
// the test adds them itself: file 0 a CT with the CT presets, file 1 an
// "MR" with the MR presets and look mr-default (the page decides its menu
// from them; the server renders the real file). It says which in its
// output ("presets_from").
//
//   node page-test.mjs --cdvol target/debug/cdvol --file head.cdv
//        [--file2 mr.cdv] [--page page.html] [--out DIR]
//
// --page: the page to test instead of the one the binary embeds (checked
// the same way against the page before issue 51: every check above
// failed there). Exit status 1 when a check fails.

import { mkdtempSync, mkdirSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { launch, parseArgs, startServer, substitutePage } from "./common.mjs";

const args = parseArgs(process.argv.slice(2));
const opt = {
  cdvol: resolve(args.cdvol ?? "target/debug/cdvol"),
  file: resolve(args.file ?? ""),
  file2: resolve(args.file2 ?? args.file ?? ""),
  page: args.page ? resolve(args.page) : null,
  out: args.out ? resolve(args.out) : mkdtempSync(join(tmpdir(), "cdvol-page-")),
  chromium: args.chromium ?? "/usr/bin/chromium",
};
mkdirSync(opt.out, { recursive: true });
const WAIT = 60000;
const results = [];
function check(name, ok, detail) {
  results.push({ name, ok: !!ok, detail });
  console.log(`${ok ? "ok  " : "FAIL"} ${name}${detail ? ": " + detail : ""}`);
}

// The first answer that is not a 409 (superseded) to an image request
// made since the change `act` makes: {status, text, query}.
async function answerTo(page, act) {
  const since = new Set();
  const made = (r) => { if (r.url().includes("/api/image?")) since.add(r); };
  page.on("request", made);
  const answer = page.waitForResponse((r) => since.has(r.request()) && r.status() !== 409, { timeout: WAIT });
  let r;
  try {
    await act();
    r = await answer;
  } finally {
    page.off("request", made);
  }
  // The body of a request the page has since superseded may be gone.
  const text = r.ok() ? "" : (await r.text().catch(() => "(body gone)")).trim();
  return { status: r.status(), text, query: new URL(r.url()).searchParams };
}
// Sets a control the way a user's edit does: its value, then `change`.
function setControl(page, id, value) {
  return page.evaluate(([id, value]) => {
    const el = document.getElementById(id);
    if (el.type === "checkbox") el.checked = value; else el.value = value;
    el.dispatchEvent(new Event("change", { bubbles: true }));
  }, [id, value]);
}
const version = (page) => page.evaluate(() => window.__cdvol.version);
async function waitFull(page, v) {
  await page.waitForFunction((v) => window.__cdvol.lastFull && window.__cdvol.lastFull.version >= v,
    v, { timeout: WAIT });
}
// A control change that must render: the full frame of the new state.
async function rendered(page, act) {
  const a = await answerTo(page, act);
  if (a.status === 200) await waitFull(page, await version(page));
  return a;
}
// Visible elements with text that lie over the image and are on top
// there (elementFromPoint), each with its text and font size.
function textOverImage(page) {
  return page.evaluate(() => {
    const view = document.getElementById("view"), c = view.getBoundingClientRect();
    const out = [];
    for (const el of document.body.querySelectorAll("*")) {
      if (el === view || el.contains(view) || !el.innerText || !el.innerText.trim()) continue;
      const r = el.getBoundingClientRect(), st = getComputedStyle(el);
      if (!r.width || !r.height || st.visibility === "hidden" || +st.opacity === 0) continue;
      const x0 = Math.max(r.left, c.left), x1 = Math.min(r.right, c.right);
      const y0 = Math.max(r.top, c.top), y1 = Math.min(r.bottom, c.bottom);
      if (x1 <= x0 || y1 <= y0) continue;
      const top = document.elementFromPoint((x0 + x1) / 2, (y0 + y1) / 2);
      if (!top || !(el.contains(top) || top.contains(el))) continue;
      out.push({ text: el.innerText.trim(), fontPx: parseFloat(st.fontSize), color: st.color });
    }
    return out;
  });
}
// The image on the canvas: how many pixels are not black, and a copy.
function canvasPixels(page) {
  return page.evaluate(() => {
    const c = document.getElementById("view");
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let lit = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] > 24) lit++;
    return { w: c.width, h: c.height, lit, data: Array.from(d.filter((_, i) => i % 4 !== 3)) };
  });
}
function meanDiff(a, b) {
  if (a.data.length !== b.data.length) return Infinity;
  let s = 0;
  for (let i = 0; i < a.data.length; i++) s += Math.abs(a.data[i] - b.data[i]);
  return s / a.data.length;
}
// How the input `id` is drawn (outline, border, shadow, background), and
// whether any of it is red; the server's message near it (inside its
// fieldset, outside the image overlay).
function inputMarks(page, id, msg) {
  return page.evaluate(([id, msg]) => {
    const el = document.getElementById(id), st = getComputedStyle(el);
    const look = [st.outlineStyle, st.outlineColor, st.outlineWidth, st.borderTopColor, st.boxShadow,
      st.backgroundColor].join(" ");
    const reds = [...look.matchAll(/rgba?\((\d+), (\d+), (\d+)/g)]
      .some(([, r, g, b]) => +r > 150 && +r > +g + 60 && +r > +b + 60);
    const box = el.closest("fieldset") || el.parentElement;
    const head = msg.slice(0, 40);
    const near = [...box.querySelectorAll("*")].some((e) => e.innerText && e.innerText.includes(head) &&
      e.getBoundingClientRect().height > 0 && !e.closest("#view, #overlay"));
    return { look, reds, near };
  }, [id, msg]);
}
const plainLook = (page, id) => page.evaluate((id) => {
  const st = getComputedStyle(document.getElementById(id));
  return [st.outlineStyle, st.outlineColor, st.outlineWidth, st.borderTopColor, st.boxShadow,
    st.backgroundColor].join(" ");
}, id);
const presetMenu = (page) => page.evaluate(() =>
  [...document.getElementById("preset").options].map((o) => o.value).filter((v) => v !== ""));
const commandText = (page) => page.evaluate(() => document.getElementById("cmd").textContent.trim());

async function openPage(browser, url, hash, setup) {
  const context = await browser.newContext({ viewport: { width: 900, height: 700 } });
  await substitutePage(context, opt.page);
  if (setup) await setup(context);
  const page = await context.newPage();
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(url + hash, { timeout: WAIT });
  await page.waitForFunction(() => window.__cdvol && window.__cdvol.ready, null, { timeout: WAIT });
  return { context, page, errors };
}

let server = null;

async function main() {
  const { proc, url } = await startServer(opt.cdvol, [opt.file, opt.file2], ["--cache-mb", "128"]);
  server = proc;
  const browser = await launch(opt.chromium);
  const out = { files: [opt.file, opt.file2], page: opt.page ?? "the binary's" };
  try {
    // /api/info, with files[i].presets added when the server gives none.
    const real = await (await fetch(url + "api/info")).json();
    const fromServer = real.files.every((f) => Array.isArray(f.presets));
    out.presets_from = fromServer ? "server" : "test (the server gives no files[i].presets)";
    const info = structuredClone(real);
    if (!fromServer) {
      const of = (m) => real.presets.filter((p) => p.modality === m);
      Object.assign(info.files[0], { modality: "CT", modality_source: "added by page-test",
        look: null, presets: of("CT") });
      Object.assign(info.files[1], { modality: "MR", modality_source: "added by page-test",
        look: "mr-default", presets: of("MR") });
    }
    const withInfo = async (context) => {
      if (fromServer) return;
      await context.route((u) => u.pathname === "/api/info",
        (route) => route.fulfill({ status: 200, contentType: "application/json", body: JSON.stringify(info) }));
    };
    const hash = "#size=512&az=30&el=10&preset=";
    const { page, errors } = await openPage(browser, url, hash, withInfo);
    await waitFull(page, 1);

    // A refused request: its message over the image, the image kept.
    const before = await canvasPixels(page);
    const refused = await answerTo(page, () => setControl(page, "iso", "200"));
    await page.waitForTimeout(300);
    out.refused = { status: refused.status, text: refused.text };
    if (refused.status !== 400) throw new Error(`iso 200 was not refused: ${refused.status} (the test needs a file prepared above 200)`);
    const over = (await textOverImage(page)).filter((t) => t.text.includes(refused.text.slice(0, 60)));
    check("error-over-image", over.length && over.every((t) => t.fontPx >= 13),
      over.length ? `font ${over[0].fontPx} px` : "the message is not over the image");
    const after = await canvasPixels(page);
    const diff = meanDiff(before, after);
    check("image-stays", before.lit > 1000 && after.lit >= before.lit * 0.99 && diff < 1,
      `non-black pixels ${before.lit} -> ${after.lit}, mean difference ${diff.toFixed(3)}`);
    await page.screenshot({ path: join(opt.out, "refused.png") });

    // The refused iso on its input; the next change of another control.
    const plain = await plainLook(page, "window");
    const marks = await inputMarks(page, "iso", refused.text);
    check("bad-iso-marked", marks.reds && marks.look !== plain && marks.near,
      `red ${marks.reds}, differs from another input ${marks.look !== plain}, message next to it ${marks.near}`);
    const next = await rendered(page, () => setControl(page, "hit", "bisect"));
    const left = await textOverImage(page);
    check("next-change-renders", next.status === 200 && !left.length,
      `status ${next.status}, iso sent ${next.query.get("iso")}` + (next.text ? `: ${next.text}` : "") +
      (left.length ? `; still over the image: ${left[0].text.slice(0, 80)}` : ""));

    // A value no number: sent, refused, marked; the next change renders.
    const abc = await answerTo(page, () => setControl(page, "iso", "abc"));
    await page.waitForTimeout(300);
    const abcMarks = abc.status === 400 ? await inputMarks(page, "iso", abc.text) : null;
    const shadows = abc.status === 400 ? await rendered(page, () => setControl(page, "shadows", true)) : null;
    check("abc-refused-then-recovers", abc.query.get("iso") === "abc" && abc.status === 400 &&
      abcMarks.reds && abcMarks.near && shadows.status === 200,
      `iso sent ${abc.query.get("iso")}, status ${abc.status}` +
      (abcMarks ? `, marked ${abcMarks.reds && abcMarks.near}, then ${shadows.status} ${shadows.text}` : ""));

    // The command is the server's after full frames: an orbit, a pan.
    await rendered(page, () => setControl(page, "shadows", false));
    const orbitCmd = [await commandText(page), await page.evaluate(() => window.__cdvol.lastFull.stats.command)];
    const box = await page.locator("#view").boundingBox();
    const x0 = box.x + box.width / 2, y0 = box.y + box.height / 2;
    await page.keyboard.down("Shift");
    await page.mouse.move(x0, y0); await page.mouse.down();
    for (let i = 1; i <= 8; i++) { await page.mouse.move(x0 + 5 * i, y0 + 3 * i); await page.waitForTimeout(20); }
    await page.mouse.up(); await page.keyboard.up("Shift");
    await waitFull(page, await version(page));
    const panCmd = [await commandText(page), await page.evaluate(() => window.__cdvol.lastFull.stats.command)];
    check("command-is-servers", orbitCmd[0] === orbitCmd[1] && panCmd[0] === panCmd[1] && panCmd[1].includes("--eye"),
      orbitCmd[0] !== orbitCmd[1] ? `page "${orbitCmd[0]}" server "${orbitCmd[1]}"`
        : panCmd[0] !== panCmd[1] || !panCmd[1].includes("--eye") ? `page "${panCmd[0]}" server "${panCmd[1]}"`
        : "an orbit and a pan");

    // The first wheel notch zooms from the frame the server placed (it
    // fits the object), not from the whole volume's.
    const placed = await page.evaluate(() => window.__cdvol.lastFull.stats.frame_mm);
    const zoom = await answerTo(page, () => page.mouse.wheel(0, 100));
    const asked = +zoom.query.get("frame");
    check("zoom-from-placed-frame", placed > 0 && Math.abs(asked / (placed * 1.1) - 1) < 0.01,
      `frame ${asked} after one notch from the placed ${placed} mm`);
    await waitFull(page, await version(page));

    // The preset menu follows the file.
    const menu0 = await presetMenu(page);
    const want0 = info.files[0].presets.map((p) => p.name);
    check("preset-menu-file-0", JSON.stringify(menu0) === JSON.stringify(want0),
      `menu ${menu0.join(",")}; file 0 offers ${want0.join(",")}`);
    // A preset file 0 offers that renders in surface mode here (one
    // without an iso value: the file's iso stays), to see what the switch
    // does with it.
    const kept = (info.files[0].presets.find((p) => p.iso == null) ?? info.files[0].presets[0])?.name ?? "";
    await rendered(page, () => setControl(page, "preset", kept));
    await rendered(page, () => setControl(page, "file", "1"));
    const menu1 = await presetMenu(page);
    const want1 = info.files[1].presets.map((p) => p.name);
    check("preset-menu-file-1", JSON.stringify(menu1) === JSON.stringify(want1),
      `menu ${menu1.join(",")}; file 1 offers ${want1.join(",")}`);
    const chosen = await page.evaluate(() => document.getElementById("preset").value);
    const expected = info.files[1].look ?? (want1.includes(kept) ? kept : "");
    check("file-switch-preset", chosen === expected, `preset ${JSON.stringify(chosen)}, expected ${JSON.stringify(expected)}`);
    for (const e of errors) check("no-page-errors", false, e);
    out.commands = { orbit: orbitCmd[1], pan: panCmd[1] };
    await page.context().close();

    // Surface mode with a preset of file 0 that has no iso value (an MR
    // composite preset on a server before issue 51). When file 0 has none
    // (the server gives every preset a surface iso), the test removes the
    // iso value of its first preset from /api/info: the page must then
    // leave that preset out of a surface request (the server would take
    // its own iso value for it, outside this file's envelope).
    const info2 = structuredClone(info);
    let isoless = info2.files[0].presets.find((p) => p.iso == null);
    if (!isoless) { isoless = info2.files[0].presets[0]; isoless.iso = null; isoless.removed = true; }
    const s = await openPage(browser, url, hash, (context) => context.route((u) => u.pathname === "/api/info",
      (route) => route.fulfill({ status: 200, contentType: "application/json", body: JSON.stringify(info2) })));
    await waitFull(s.page, 1);
    const surf = await rendered(s.page, () => setControl(s.page, "preset", isoless.name));
    const mode = await s.page.evaluate(() => document.getElementById("mode").value);
    check("surface-preset-without-iso", mode === "surface" && surf.status === 200,
      `${isoless.name}${isoless.removed ? " (iso removed by the test)" : ""} in ${mode}: ` +
      `${surf.status} ${surf.text}, preset sent ${surf.query.get("preset")}`);
    await s.context.close();

    // The command before any frame: every image request held.
    const held = [];
    const c = await openPage(browser, url, hash, async (context) => {
      await withInfo(context);
      await context.route((u) => u.pathname === "/api/image", (route) => { held.push(route); });
    });
    await c.page.click("#showcmd");
    const cmd0 = await commandText(c.page);
    await setControl(c.page, "iso", "500");
    const cmd1 = await commandText(c.page);
    await setControl(c.page, "mode", "mip");
    const cmd2 = await commandText(c.page);
    const frames = await c.page.evaluate(() => window.__cdvol.frames.length);
    check("command-before-frame", frames === 0 && held.length > 0 && cmd0.includes("--mode surface") &&
      cmd1 !== cmd0 && cmd1.includes("--iso 500") && cmd2.includes("--mode mip"),
      `frames ${frames}, held ${held.length}; before "${cmd0}", iso 500 "${cmd1}", mip "${cmd2}"`);
    for (const r of held) await r.abort().catch(() => {});
    await c.context.close();
  } finally {
    await browser.close();
    proc.kill("SIGTERM");
  }
  out.checks = results;
  writeFileSync(join(opt.out, "page-test.json"), JSON.stringify(out, null, 2) + "\n");
  const failed = results.filter((r) => !r.ok).length;
  console.log(`page-test: presets from ${out.presets_from}; ${results.length - failed} passed, ${failed} failed`);
  if (failed) process.exitCode = 1;
}

main().catch((e) => {
  console.error(e);
  if (server) console.error("cdvol serve stderr (last 4000 bytes):\n" + (server.stderrText ?? ""));
  const failed = results.filter((r) => !r.ok).length;
  console.log(`page-test: stopped; ${results.length - failed} passed, ${failed + 1} failed`);
  process.exit(1);
});
