// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "viewer/RelightScene.h"

#include <atomic>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::viewer {

struct ViewServerOptions {
    std::string bind = "127.0.0.1";  ///< address to listen on (loopback by default)
    int port = 8080;                 ///< 0: any free port (ViewServer::port() tells which)
    std::string webRoot;             ///< the page: index.html, src/, node_modules/three
    int threads = 0;                 ///< the engine's worker threads (0: every core)
    /// An update whose values take at least this many bytes (a whole cache) sends them by HTTP
    /// (/api/body/ID) and its header alone on the WebSocket: Chromium takes a 1.5 MB WebSocket
    /// message in about 26 ms, the same bytes by fetch() in about 5 ms (docs/viewer-protocol.md).
    std::size_t httpBodyBytes = 256 * 1024;
    /// Host names a request may name besides loopback (localhost, 127.0.0.0/8, [::1]) and the
    /// bound address: the names a remote viewer reaches this machine by when it binds to all
    /// interfaces (`pmsc view --allow-host NAME`). See hostAllowed().
    std::vector<std::string> allowedHosts;
    /// Origins (scheme://host[:port]) whose pages may use the API and drive the session besides the
    /// server's own page: for a user who deliberately serves a page of their own elsewhere
    /// (`pmsc view --allow-origin ORIGIN`). See sameOrigin().
    std::vector<std::string> allowedOrigins;
};

/// Whether a request whose Host header is `host` may be answered: its name (the port taken off)
/// is loopback, the address the server is bound to, or one of `allowed`. Why: a web page the user
/// visits can make the browser send requests to 127.0.0.1 under a name of its own (DNS rebinding);
/// the Host header carries that name, so only names that mean this machine are answered.
bool hostAllowed(const std::string& host, const std::string& bind, const std::vector<std::string>& allowed);

/// Whether a request with headers Origin `origin` (empty: none, a client that is not a browser)
/// and Host `host` comes from the server's own page or an origin the user allowed: no Origin, an
/// Origin of http://HOST exactly, or one of `allowed` exactly (case aside). Why: a browser lets any
/// page open a WebSocket to any address and sends the page's origin with it; only the page this
/// server served, and pages the user named, may drive the session.
bool sameOrigin(const std::string& origin, const std::string& host,
                const std::vector<std::string>& allowed = {});

/// The page's folder: PMSC_VIEW_WEB if set, else the installed share/pmsc/web/viewer beside the
/// program's prefix if it exists, else the source tree's web/viewer the build was made from.
std::string defaultWebRoot();

/// `pmsc view`'s server: the page and its files over HTTP, the scene's description and geometry
/// (/api/scene, /api/geometry), and one viewer's relighting over a WebSocket (/api/ws, a
/// RelightSession). Boost.Beast on one I/O thread (the caller of run()); the relighting runs on
/// the session's thread and the engine's arena, and its updates are posted to the I/O thread.
/// One viewer at a time: a second WebSocket gets an error message and is closed. Only GET
/// requests for the page's files and the API are answered; everything else is 404 or 405. A
/// request whose Host is not this machine's (hostAllowed) or whose Origin is another site's
/// (sameOrigin) gets 403 and nothing else, the WebSocket upgrade included.
/// The protocol: docs/viewer.md.
class ViewServer {
public:
    /// Binds and listens. @throws pmsc::InputError (one line) if the address cannot be bound,
    ///         the web root has no index.html, or the model does not match the scene.
    ViewServer(const Model& model, const RelightScene& scene, ViewServerOptions options);
    ~ViewServer();
    ViewServer(const ViewServer&) = delete;
    ViewServer& operator=(const ViewServer&) = delete;

    /// The port it listens on.
    int port() const;
    /// Serves until `stop` is set (checked every 100 ms), then closes every connection.
    void run(const std::atomic<bool>& stop);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pmsc::viewer
