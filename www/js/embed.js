// Embed mode (`?embed=1`): the page as an interactive figure in another page's iframe.
// Only the 3D view, the frame timeline and one small card are shown: the joints' sliders
// once a model is on view, or the Fit button and the fit's progress for an example fitted
// in place (`?example=NAME&fit=1&embed=1`). A link opens the same view in the full page.
// The panel's own elements are moved into the card, so they keep their handlers.

const $ = (id) => document.getElementById(id);

export const EMBED = new URLSearchParams(location.search).get('embed') === '1';

/** The card's elements, in order; which of them show depends on `has-result`. */
const FIT_IDS = ['fit-actions', 'fit-status', 'progress'];
const RESULT_IDS = ['joint-list', 'joint-actions'];

/** Below this view width the card starts folded, so the figure is not covered. */
const FOLD_BELOW_PX = 560;

/**
 * Switches the page into embed mode. `fullUrl()` gives the full page's URL for the
 * current view (the embed parameter dropped, the camera kept).
 */
export function setupEmbed({ fullUrl }) {
  if (!EMBED) return;
  document.body.classList.add('embed');
  const body = $('embed-body');
  for (const id of [...FIT_IDS, ...RESULT_IDS]) body.appendChild($(id));
  setOpen(window.innerWidth >= FOLD_BELOW_PX);
  $('embed-toggle').addEventListener('click', () => setOpen($('embed-toggle').getAttribute('aria-expanded') !== 'true'));
  const link = $('embed-open');
  link.hidden = false;
  // The camera moves after load, so the link is written when it is about to be followed.
  const refresh = () => { link.href = fullUrl(); };
  refresh();
  for (const ev of ['pointerdown', 'focus', 'mouseenter']) link.addEventListener(ev, refresh);
}

function setOpen(open) {
  $('embed-toggle').setAttribute('aria-expanded', String(open));
  $('embed-body').hidden = !open;
  $('embed-card').classList.toggle('folded', !open);
}

/**
 * Shows the card's fit part or its result part. `joints`: the model's joint count
 * (null without a model); `fitting`: a fit is running; `frames`: frames are loaded.
 */
export function syncEmbed({ joints, fitting, frames }) {
  if (!EMBED) return;
  const card = $('embed-card');
  const result = joints !== null && !fitting;
  card.classList.toggle('has-result', result);
  card.hidden = !(result || fitting || frames);
  const toggle = $('embed-toggle');
  toggle.textContent = result ? `Joints (${joints})` : (fitting ? 'Fitting…' : 'Fit');
}

/** The full page's URL for an embed URL: the same view without `embed`. */
export function withoutEmbed(href) {
  const url = new URL(href);
  url.searchParams.delete('embed');
  return url.toString();
}

/** An iframe element's HTML showing `src`, for a project page. */
export function iframeCode(src, title) {
  const esc = (s) => String(s).replace(/&/g, '&amp;').replace(/"/g, '&quot;').replace(/</g, '&lt;');
  return `<iframe src="${esc(src)}" title="${esc(title)}" width="720" height="480" `
    + 'style="border:0;border-radius:8px;max-width:100%" loading="lazy" allowfullscreen></iframe>';
}

/**
 * `url` as text with a readable query: `/` and `:` stay unescaped (RFC 3986 allows both
 * in a query), so a model URL inside a link can be read and replaced by hand.
 */
export function readableUrl(url) {
  const enc = (v) => encodeURIComponent(v).replace(/%2F/gi, '/').replace(/%3A/gi, ':');
  const q = [...url.searchParams].map(([k, v]) => `${enc(k)}=${enc(v)}`).join('&');
  return `${url.origin}${url.pathname}${q ? `?${q}` : ''}${url.hash}`;
}
