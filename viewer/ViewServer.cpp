// The only file that includes Boost.Beast and Boost.Asio (heavy headers), behind ViewServer.h.
#include "viewer/ViewServer.h"

#include "pmsc/Errors.h"
#include "viewer/RelightSession.h"

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>

namespace pmsc::viewer {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

namespace {

std::string contentType(const std::string& path) {
    const std::string ext = std::filesystem::path(path).extension().string();
    if (ext == ".html") return "text/html; charset=utf-8";
    if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
    if (ext == ".css") return "text/css; charset=utf-8";
    if (ext == ".json" || ext == ".map") return "application/json";
    if (ext == ".png") return "image/png";
    if (ext == ".svg") return "image/svg+xml";
    return "application/octet-stream";
}

/// The file a URL path names under the web root, or empty: only the page's own prefixes, no "..".
std::string fileOf(const std::string& root, std::string target) {
    target = target.substr(0, target.find_first_of("?#"));
    if (target.find("..") != std::string::npos || target.find('\\') != std::string::npos) return {};
    struct Prefix {
        const char* url;
        const char* dir;
    };
    static const Prefix prefixes[] = {{"/app/", "src/"},
                                      {"/vendor/three/", "node_modules/three/build/"},
                                      {"/vendor/three-addons/", "node_modules/three/examples/jsm/"}};
    if (target == "/" || target == "/index.html") return root + "/index.html";
    for (const Prefix& p : prefixes) {
        const std::string url = p.url;
        if (target.compare(0, url.size(), url) == 0 && target.size() > url.size())
            return root + "/" + p.dir + target.substr(url.size());
    }
    return {};
}

bool readWhole(const std::string& path, std::string& out) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) return false;
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    if (!in.good() && !in.eof()) return false;
    out = s.str();
    return true;
}

std::string lowered(std::string s) {
    for (char& ch : s) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return s;
}

}  // namespace

bool hostAllowed(const std::string& host, const std::string& bind, const std::vector<std::string>& allowed) {
    // The name without the port: "[::1]:8080" -> "::1", "127.0.0.1:8080" -> "127.0.0.1".
    std::string name;
    if (!host.empty() && host.front() == '[') {
        const auto close = host.find(']');
        if (close == std::string::npos) return false;
        const std::string rest = host.substr(close + 1);
        if (!rest.empty() && rest.front() != ':') return false;
        name = host.substr(1, close - 1);
    } else {
        const auto colon = host.find(':');
        if (colon != std::string::npos && host.find(':', colon + 1) != std::string::npos) return false;
        name = host.substr(0, colon);
    }
    name = lowered(name);
    if (name.empty()) return false;
    if (name == "localhost" || name == lowered(bind)) return true;
    boost::system::error_code ec;
    const auto address = net::ip::make_address(name, ec);
    if (!ec && address.is_loopback()) return true;
    for (const std::string& a : allowed)
        if (lowered(a) == name) return true;
    return false;
}

bool sameOrigin(const std::string& origin, const std::string& host, const std::vector<std::string>& allowed) {
    if (origin.empty() || lowered(origin) == "http://" + lowered(host)) return true;
    for (const std::string& a : allowed)
        if (lowered(a) == lowered(origin)) return true;
    return false;
}

std::string defaultWebRoot() {
    if (const char* env = std::getenv("PMSC_VIEW_WEB"); env && *env) return env;
    std::error_code ec;
    const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        const auto installed = exe.parent_path().parent_path() / "share" / "pmsc" / "web" / "viewer";
        if (std::filesystem::is_regular_file(installed / "index.html", ec)) return installed.string();
    }
    return PMSC_WEB_DIR;
}

struct ViewServer::Impl {
    const Model& model;
    const RelightScene& scene;
    ViewServerOptions options;
    std::string sceneJson;
    std::string geometry;
    net::io_context ioc{1};
    tcp::acceptor acceptor{ioc};

    class WsConnection;
    std::weak_ptr<WsConnection> viewer;  ///< the one connected viewer (I/O thread only)

    /// Bodies not yet fetched, by URL (I/O thread only). Each is served once and then let go (moved
    /// into its response, no copy); at most kBodiesKept wait, the oldest beyond that are gone (404),
    /// so a page that never fetches costs bounded memory (the page fetches each as its text arrives).
    static constexpr std::size_t kBodiesKept = 32;
    std::deque<std::pair<std::string, std::string>> bodies;
    std::atomic<std::uint64_t> nextBody{0};

    /// A waiting GET /api/body/next (I/O thread only): answered with the next body the moment it
    /// is made, so a whole cache starts on its way without the page's request after the WebSocket
    /// header (measured in Chromium on the volume demo: about 5 ms of a hit's 30-40). One waits at
    /// a time; a newer request replaces it (its page left or reloaded), and the older connection
    /// is let go. Declared after `ioc`: destroyed before it.
    using BodyWaiter = std::function<void(std::string url, std::string bytes)>;
    BodyWaiter bodyWaiter;

    void keepBody(const std::string& url, std::string bytes) {
        if (bodyWaiter) {
            BodyWaiter waiter = std::move(bodyWaiter);
            bodyWaiter = nullptr;
            waiter(url, std::move(bytes));
            return;
        }
        bodies.emplace_back(url, std::move(bytes));
        while (bodies.size() > kBodiesKept) bodies.pop_front();
    }

    /// GET /api/body/next: the oldest body not yet fetched at once, else the next one made.
    void waitForBody(BodyWaiter waiter) {
        if (!bodies.empty()) {
            auto [url, bytes] = std::move(bodies.front());
            bodies.pop_front();
            waiter(url, std::move(bytes));
            return;
        }
        bodyWaiter = std::move(waiter);
    }

    Impl(const Model& m, const RelightScene& s, ViewServerOptions o)
        : model(m), scene(s), options(std::move(o)) {
        std::error_code fe;
        if (!std::filesystem::is_regular_file(options.webRoot + "/index.html", fe))
            throw InputError("view: no index.html in the web root '" + options.webRoot + "' (--web DIR)");
        nlohmann::json j = scene.describe();
        j["controls"] = nlohmann::json::array();
        for (const Control& c : scene.controls()) {
            j["controls"].push_back({{"name", c.name},
                                     {"label", c.label},
                                     {"unit", c.unit},
                                     {"min", c.min},
                                     {"max", c.max},
                                     {"step", c.step},
                                     {"value", c.value}});
        }
        j["light"] = scene.light(scene.defaults());
        j["model"] = {{"basis", model.basis.cols()},
                      {"keys", model.keyCount()},
                      {"eps_min", model.epsMin},
                      {"eps_max", model.epsMax},
                      {"key_error", toString(model.keyErrorNorm)}};
        sceneJson = j.dump();
        geometry = scene.geometry();
        if (model.points != scene.pointCount())
            throw InputError("view: the model has " + std::to_string(model.points) + " points, the " +
                             scene.kind() + " scene " + std::to_string(scene.pointCount()) +
                             ": train it on this scene's frames (pmsc demo " + scene.kind() +
                             " --out DIR writes DIR/model.pmsc and DIR/scene.txt)");
        boost::system::error_code ec;
        const auto address = net::ip::make_address(options.bind, ec);
        if (ec) throw InputError("view: --bind '" + options.bind + "' is not an IP address");
        const tcp::endpoint endpoint(address, static_cast<unsigned short>(options.port));
        acceptor.open(endpoint.protocol(), ec);
        if (!ec) acceptor.set_option(net::socket_base::reuse_address(true), ec);
        if (!ec) acceptor.bind(endpoint, ec);
        if (!ec) acceptor.listen(net::socket_base::max_listen_connections, ec);
        if (ec)
            throw InputError("view: cannot listen on " + options.bind + ":" + std::to_string(options.port) +
                             ": " + ec.message());
    }

    void accept();
    /// Answers a GET; a body (/api/body/ID) leaves the store with its answer.
    http::response<http::string_body> respond(const http::request<http::string_body>& req);
    /// Why a request is not answered (hostAllowed, sameOrigin), or empty when it may be.
    std::string refusal(const http::request<http::string_body>& req) const;
    /// 403 with the reason, and the connection closed after it.
    static http::response<http::string_body> forbidden(const http::request<http::string_body>& req,
                                                       const std::string& why);
    /// A body's answer: its bytes, and its address in the X-Pmsc-Body header (the `body` of the
    /// update it belongs to).
    static http::response<http::string_body> bodyResponse(const http::request<http::string_body>& req,
                                                          const std::string& url, std::string bytes);
};

/// One viewer's WebSocket: reads client messages into its RelightSession, writes the session's
/// updates in order (text, then its binary part).
class ViewServer::Impl::WsConnection : public std::enable_shared_from_this<WsConnection> {
public:
    WsConnection(Impl& server, tcp::socket socket) : server_(server), ws_(std::move(socket)) {}

    void start(http::request<http::string_body> req) {
        ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
        ws_.read_message_max(1 << 20);
        ws_.async_accept(req, [self = shared_from_this()](beast::error_code ec) { self->accepted(ec); });
    }

    /// Ends the relighting (cancels the frame in progress and joins its thread).
    void stop() { session_.reset(); }

private:
    struct Out {
        std::string data;
        bool text;
    };

    void accepted(beast::error_code ec) {
        if (ec) return;
        if (server_.viewer.lock()) {
            closing_ = true;
            queue(nlohmann::json{{"type", "error"},
                                 {"message", "another viewer is connected: pmsc view serves one at a time"}}
                      .dump(),
                  true);
            return;
        }
        server_.viewer = weak_from_this();
        queue(nlohmann::json{{"type", "hello"}, {"version", 1}}.dump(), true);
        try {
            std::weak_ptr<WsConnection> weak = weak_from_this();
            net::io_context& ioc = server_.ioc;
            const Index channels = server_.model.channels;
            Impl* server = &server_;
            session_ = std::make_unique<RelightSession>(
                server_.model, server_.scene, server_.options.threads,
                [weak, &ioc, channels, server](Update&& u) {
                    // A large binary part (a whole cache) goes by HTTP (ViewServerOptions::
                    // httpBodyBytes): the WebSocket carries the header alone (count 0) and the
                    // text the body's address; the page fetches it before it applies later updates.
                    std::string body, bin, url;
                    if (u.binaryFollows &&
                        u.halfs.size() * sizeof(std::uint16_t) >= server->options.httpBodyBytes) {
                        url = "/api/body/" + std::to_string(server->nextBody.fetch_add(1) + 1);
                        u.text["body"] = url;
                        body = u.binary(channels);
                        Update header;
                        header.seq = u.seq;
                        bin = header.binary(channels);
                    } else if (u.binaryFollows) {
                        bin = u.binary(channels);
                    }
                    std::string text = u.text.dump();
                    const bool withBinary = u.binaryFollows;
                    net::post(ioc, [weak, server, url = std::move(url), text = std::move(text),
                                    bin = std::move(bin), body = std::move(body), withBinary]() mutable {
                        if (!url.empty()) server->keepBody(url, std::move(body));
                        if (auto self = weak.lock()) {
                            self->queue(std::move(text), true);
                            if (withBinary) self->queue(std::move(bin), false);
                        }
                    });
                });
        } catch (const std::exception& e) {
            closing_ = true;
            queue(nlohmann::json{{"type", "error"}, {"message", e.what()}}.dump(), true);
            return;
        }
        read();
    }

    void read() {
        ws_.async_read(buffer_,
                       [self = shared_from_this()](beast::error_code ec, std::size_t) { self->onRead(ec); });
    }

    void onRead(beast::error_code ec) {
        if (ec) {
            // Closed or broken: stop the relighting (cancels the frame in progress) and let go.
            session_.reset();
            return;
        }
        const bool text = ws_.got_text();
        const std::string message = beast::buffers_to_string(buffer_.data());
        buffer_.consume(buffer_.size());
        try {
            if (!text)
                throw InputError("binary messages are not part of the viewer protocol (send JSON text)");
            session_->receive(message);
        } catch (const std::exception& e) {
            queue(nlohmann::json{{"type", "error"}, {"message", e.what()}}.dump(), true);
        }
        read();
    }

    void queue(std::string data, bool text) {
        out_.push_back({std::move(data), text});
        if (!writing_) write();
    }

    void write() {
        if (out_.empty()) {
            writing_ = false;
            if (closing_) {
                ws_.async_close(websocket::close_code::try_again_later,
                                [self = shared_from_this()](beast::error_code) {});
            }
            return;
        }
        writing_ = true;
        ws_.text(out_.front().text);
        ws_.async_write(net::buffer(out_.front().data),
                        [self = shared_from_this()](beast::error_code ec, std::size_t) {
                            self->out_.pop_front();
                            if (ec) {
                                self->out_.clear();
                                self->writing_ = false;
                                return;
                            }
                            self->write();
                        });
    }

    Impl& server_;
    websocket::stream<beast::tcp_stream> ws_;
    beast::flat_buffer buffer_;
    std::unique_ptr<RelightSession> session_;
    std::deque<Out> out_;
    bool writing_ = false;
    bool closing_ = false;
};

namespace {

/// One HTTP connection: requests answered in turn until the client closes, or handed to a
/// WsConnection on an upgrade to /api/ws.
template <class Server>
class HttpConnection : public std::enable_shared_from_this<HttpConnection<Server>> {
public:
    HttpConnection(Server& server, tcp::socket socket) : server_(server), stream_(std::move(socket)) {}

    void read() {
        req_ = {};
        stream_.expires_after(std::chrono::seconds(60));
        http::async_read(
            stream_, buffer_, req_,
            [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->onRead(ec); });
    }

private:
    void onRead(beast::error_code ec) {
        if (ec) return;  // closed, timed out or malformed: Beast has nothing to answer
        if (const std::string why = server_.refusal(req_); !why.empty()) {
            res_ = Server::forbidden(req_, why);
            write();
            return;
        }
        if (websocket::is_upgrade(req_)) {
            if (req_.target() == "/api/ws") {
                stream_.expires_never();
                std::make_shared<typename Server::WsConnection>(server_, stream_.release_socket())
                    ->start(std::move(req_));
                return;
            }
        }
        if (req_.target() == "/api/body/next" && req_.method() == http::verb::get) {
            stream_.expires_never();  // waits for the next frame however long the user pauses
            server_.waitForBody([self = this->shared_from_this()](std::string url, std::string bytes) {
                self->res_ = Server::bodyResponse(self->req_, url, std::move(bytes));
                self->write();
            });
            return;
        }
        res_ = server_.respond(req_);
        write();
    }

    void write() {
        http::async_write(stream_, res_, [self = this->shared_from_this()](beast::error_code e, std::size_t) {
            if (e) return;
            if (self->res_.need_eof()) {
                beast::error_code ignored;
                self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
                return;
            }
            self->read();
        });
    }

    Server& server_;
    beast::tcp_stream stream_;
    beast::flat_buffer buffer_;
    http::request<http::string_body> req_;
    http::response<http::string_body> res_;
};

}  // namespace

namespace {
http::response<http::string_body> answerTo(const http::request<http::string_body>& req) {
    http::response<http::string_body> res;
    res.version(req.version());
    res.keep_alive(req.keep_alive());
    res.set(http::field::server, "pmsc view");
    res.set(http::field::cache_control, "no-store");
    return res;
}
}  // namespace

http::response<http::string_body> ViewServer::Impl::bodyResponse(const http::request<http::string_body>& req,
                                                                 const std::string& url, std::string bytes) {
    http::response<http::string_body> res = answerTo(req);
    res.result(http::status::ok);
    res.set(http::field::content_type, "application/octet-stream");
    res.set("X-Pmsc-Body", url);
    res.body() = std::move(bytes);
    res.prepare_payload();
    return res;
}

std::string ViewServer::Impl::refusal(const http::request<http::string_body>& req) const {
    const std::string host(req[http::field::host]);
    if (!hostAllowed(host, options.bind, options.allowedHosts))
        return host.empty()
                   ? "a request must name its Host"
                   : "host '" + host + "' is not this machine's (pmsc view --allow-host NAME adds one)";
    const std::string origin(req[http::field::origin]);
    if (!sameOrigin(origin, host, options.allowedOrigins))
        return "origin '" + origin + "' is not this server's page (pmsc view --allow-origin ORIGIN adds one)";
    return {};
}

http::response<http::string_body> ViewServer::Impl::forbidden(const http::request<http::string_body>& req,
                                                              const std::string& why) {
    http::response<http::string_body> res = answerTo(req);
    res.result(http::status::forbidden);
    res.keep_alive(false);
    res.set(http::field::content_type, "text/plain");
    res.body() = "pmsc view: " + why + "\n";
    res.prepare_payload();
    return res;
}

http::response<http::string_body> ViewServer::Impl::respond(const http::request<http::string_body>& req) {
    http::response<http::string_body> res = answerTo(req);
    auto reply = [&](http::status status, std::string type, std::string body) {
        res.result(status);
        res.set(http::field::content_type, type);
        res.body() = std::move(body);
        res.prepare_payload();
        return res;
    };
    if (req.method() != http::verb::get && req.method() != http::verb::head)
        return reply(http::status::method_not_allowed, "text/plain", "pmsc view answers GET only\n");
    const std::string target(req.target());
    if (target == "/api/scene") return reply(http::status::ok, "application/json", sceneJson);
    if (target == "/api/geometry") return reply(http::status::ok, "application/octet-stream", geometry);
    if (target.rfind("/api/body/", 0) == 0) {
        for (auto it = bodies.begin(); it != bodies.end(); ++it) {
            if (it->first != target) continue;
            std::string bytes = std::move(it->second);
            bodies.erase(it);
            return bodyResponse(req, target, std::move(bytes));
        }
        return reply(http::status::not_found, "text/plain",
                     "no such body (fetched or superseded): " + target + "\n");
    }
    const std::string path = fileOf(options.webRoot, target);
    std::string body;
    if (path.empty() || !readWhole(path, body))
        return reply(http::status::not_found, "text/plain", "not found: " + target + "\n");
    return reply(http::status::ok, contentType(path), std::move(body));
}

void ViewServer::Impl::accept() {
    acceptor.async_accept([this](beast::error_code ec, tcp::socket socket) {
        if (!ec) {
            // Each update is a small text message then its binary part: without TCP_NODELAY the
            // second waits for the first's delayed ACK (Nagle), tens of milliseconds a move.
            beast::error_code ignored;
            socket.set_option(tcp::no_delay(true), ignored);
            std::make_shared<HttpConnection<Impl>>(*this, std::move(socket))->read();
        }
        if (acceptor.is_open()) accept();
    });
}

ViewServer::ViewServer(const Model& model, const RelightScene& scene, ViewServerOptions options)
    : impl_(std::make_unique<Impl>(model, scene, std::move(options))) {}

ViewServer::~ViewServer() = default;

int ViewServer::port() const { return impl_->acceptor.local_endpoint().port(); }

void ViewServer::run(const std::atomic<bool>& stop) {
    impl_->accept();
    while (!stop.load()) impl_->ioc.run_for(std::chrono::milliseconds(100));
    // The session's thread posts to the I/O context: end it while the context still exists.
    if (auto v = impl_->viewer.lock()) v->stop();
    beast::error_code ec;
    impl_->acceptor.close(ec);
    impl_->ioc.stop();
}

}  // namespace pmsc::viewer
