//! The page skeleton: one style sheet for the screen (a laptop at 100 %)
//! and for print (A4 portrait, charts never split across pages).

use super::esc;

/// Shared style. Sizes are in rem so a reader's browser zoom scales all
/// of it; charts scale to the column width (their SVG has a viewBox).
const STYLE: &str = r#"
:root{--ink:#1d1d1d;--muted:#555;--rule:#c8c8c8;--pass:#1b7f3b;--fail:#b3261e;--error:#8a5a00;--aborted:#555}
html{font-size:16px}
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:1.5rem auto;max-width:62rem;padding:0 1rem;color:var(--ink);line-height:1.45}
h1{font-size:1.6rem;margin:.4rem 0} h2{font-size:1.25rem;margin:1.6rem 0 .5rem;border-bottom:1px solid var(--rule)}
.headline{font-size:1.15rem;margin:.6rem 0 1rem}
table{border-collapse:collapse;margin:.6rem 0 1rem}
td,th{border:1px solid var(--rule);padding:.25rem .55rem;font-size:.92rem;vertical-align:top}
th{background:#f2f2f2;text-align:left}
td.num{text-align:right;font-family:ui-monospace,"DejaVu Sans Mono",monospace;white-space:nowrap}
tr.fail td{background:#fde7e6} tr.error td{background:#fff4e0} tr.conditional_pass td,tr.conditional_fail td{background:#fff4e0}
td.sign{min-width:22rem;height:2.2rem}
.verdict{font-size:2rem;font-weight:700;color:#fff;padding:.2rem .7rem;border-radius:.2rem;display:inline-block;letter-spacing:.05em}
td.outcome{font-weight:600} td.outcome.pass{color:var(--pass)} td.outcome.fail{color:var(--fail)} td.outcome.error{color:var(--error)}
.box{background:#fff4e0;border-left:4px solid var(--error);padding:.5rem .8rem;margin:.8rem 0}
.ok{background:#eaf5ec;border-left:4px solid var(--pass);padding:.5rem .8rem;margin:.8rem 0}
.note{color:var(--muted);font-size:.92rem}
figure{margin:1rem 0} figure svg{width:100%;height:auto;display:block}
figcaption{color:var(--muted);font-size:.9rem;margin-top:.2rem}
@media print{
  @page{size:A4 portrait;margin:14mm 12mm}
  html{font-size:10pt}
  body{margin:0;max-width:none;padding:0}
  h2{break-after:avoid}
  figure,table tr{break-inside:avoid}
  .verdict{-webkit-print-color-adjust:exact;print-color-adjust:exact}
  tr.fail td,tr.error td,th,.box,.ok{-webkit-print-color-adjust:exact;print-color-adjust:exact}
  a{color:inherit;text-decoration:none}
}
"#;

/// A whole page: `title` (escaped here), page-specific `css`, and the
/// already-escaped `body`.
pub fn page(title: &str, css: &str, body: &str) -> String {
    format!(
        "<!doctype html>\n<html lang=en><head><meta charset=utf-8>\
         <meta name=viewport content=\"width=device-width,initial-scale=1\">\
         <title>{}</title>\n<style>{STYLE}{css}</style></head><body>\n{body}\n</body></html>\n",
        esc(title)
    )
}
