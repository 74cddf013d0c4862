// recap view: conveniences on top of plain GET pages (everything also works without script).
// Records script errors in <body data-js-errors> and sets data-ready when done (the browser tests read both).
(function () {
  window.addEventListener('error', function (e) {
    var prev = document.body.getAttribute('data-js-errors') || '';
    document.body.setAttribute('data-js-errors', prev + (prev ? ' | ' : '') + (e.message || 'error'));
  });
  // filters apply as soon as one changes
  var form = document.getElementById('filters');
  function submitClean() {  // leave empty fields out of the URL
    form.querySelectorAll('select, input').forEach(function (el) {
      if (el.name && el.value === '' ) el.disabled = true;
    });
    form.submit();
  }
  if (form) {
    form.querySelectorAll('select').forEach(function (s) {
      s.addEventListener('change', submitClean);
    });
    form.addEventListener('submit', function (ev) { ev.preventDefault(); submitClean(); });
  }
  // expand / collapse the whole context tree
  function setAll(open) {
    document.querySelectorAll('#tree details.node').forEach(function (d) { d.open = open; });
  }
  var ex = document.getElementById('expand-all'), co = document.getElementById('collapse-all');
  if (ex) ex.addEventListener('click', function () { setAll(true); });
  if (co) co.addEventListener('click', function () { setAll(false); setTreeRootOpen(); });
  function setTreeRootOpen() {
    var first = document.querySelector('#tree ul.root > li > details.node');
    if (first) first.open = true;
  }
  // a call's window opens in the panel below the calls table (the server rebuilds it from window_seqs)
  var panel = document.getElementById('window-panel');
  document.querySelectorAll('a.window').forEach(function (a) {
    a.addEventListener('click', function (ev) {
      if (!panel || ev.ctrlKey || ev.metaKey || ev.shiftKey) return;
      ev.preventDefault();
      panel.hidden = false;
      panel.setAttribute('data-loading', a.getAttribute('data-call'));
      fetch(a.getAttribute('href') + '&fragment=1', {credentials: 'same-origin'}).then(function (r) {
        if (!r.ok) throw new Error('HTTP ' + r.status);
        return r.text();
      }).then(function (html) {
        panel.innerHTML = html;  // server-rendered, every value escaped there
        panel.removeAttribute('data-loading');
        panel.setAttribute('data-call', a.getAttribute('data-call'));
        panel.scrollIntoView({block: 'nearest'});
      }).catch(function (e) {
        panel.textContent = 'could not load the window: ' + e.message;
        panel.removeAttribute('data-loading');
      });
    });
  });
  // a search hit: show the message
  var hit = document.querySelector('li.msg.hit');
  if (hit) hit.scrollIntoView({block: 'center'});
  document.body.setAttribute('data-ready', '1');
})();
