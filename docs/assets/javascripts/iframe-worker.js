// Search from file://: browsers refuse a Web Worker whose script is a file:// URL, and Material's search runs in
// one. Opened from disk, this page's Worker runs the worker's script in a hidden same-origin iframe instead,
// and passes the messages both ways. Served over http(s), nothing changes. (Its name holds "iframe-worker" so
// that Material's offline plugin, which looks for that name among extra.polyfills, adds no script from the
// network; the code is this project's own.)
(function () {
  "use strict";
  if (location.protocol !== "file:") {
    return;
  }

  function FrameWorker(url) {
    var worker = this;
    var listeners = [];
    var waiting = [];
    var loaded = false;
    var frame = document.createElement("iframe");
    frame.hidden = true;
    frame.setAttribute("aria-hidden", "true");
    (document.body || document.documentElement).appendChild(frame);
    var inner = frame.contentWindow;

    function toPage(data) {
      var event = new MessageEvent("message", { data: data });
      if (typeof worker.onmessage === "function") {
        worker.onmessage(event);
      }
      listeners.slice().forEach(function (listener) { listener.call(worker, event); });
    }

    function toWorker(data) {
      inner.dispatchEvent(new inner.MessageEvent("message", { data: data }));
    }

    // the worker's globals: postMessage answers the page; importScripts is not needed by the English index
    inner.postMessage = toPage;
    inner.importScripts = function () {};

    var script = inner.document.createElement("script");
    script.src = new URL(url, location.href).href;
    script.onload = function () {
      loaded = true;
      waiting.splice(0).forEach(toWorker);
    };
    inner.document.head.appendChild(script);

    this.onmessage = null;
    this.onerror = null;
    this.postMessage = function (data) {
      if (loaded) {
        toWorker(data);
      } else {
        waiting.push(data);
      }
    };
    this.addEventListener = function (type, listener) {
      if (type === "message") {
        listeners.push(listener);
      }
    };
    this.removeEventListener = function (type, listener) {
      listeners = listeners.filter(function (known) { return known !== listener; });
    };
    this.terminate = function () {
      frame.remove();
    };
  }

  window.Worker = FrameWorker;
})();
