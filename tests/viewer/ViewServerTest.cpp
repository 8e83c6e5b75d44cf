// The server over real connections: HTTP for the page and the API, the WebSocket protocol, one
// viewer at a time, bad messages and a client that leaves mid-frame.
#include "pmsc/Errors.h"
#include "tests/common/MissingData.h"
#include "tests/viewer/ViewerFixture.h"
#include "viewer/ViewServer.h"

#include <gtest/gtest.h>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <thread>

namespace pmsc::viewer {
namespace {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;
using test::smallVolume;

/// A server on a free port, served by its own thread for the test's duration.
class Running {
public:
    explicit Running(const Model& model, std::size_t httpBodyBytes = 256 * 1024,
                     std::vector<std::string> allowedOrigins = {}) {
        web_ = smallVolume().dir + "/web";
        std::filesystem::create_directories(web_ + "/src");
        std::ofstream(web_ + "/index.html") << "<!doctype html><title>pmsc view</title>";
        std::ofstream(web_ + "/src/main.js") << "export const x = 1;\n";
        ViewServerOptions o;
        o.port = 0;
        o.webRoot = web_;
        o.threads = 2;
        o.httpBodyBytes = httpBodyBytes;
        o.allowedOrigins = std::move(allowedOrigins);
        server_ = std::make_unique<ViewServer>(model, *smallVolume().scene, o);
        thread_ = std::thread([this] { server_->run(stop_); });
    }
    ~Running() {
        stop_ = true;
        thread_.join();
    }
    int port() const { return server_->port(); }

private:
    std::string web_;
    std::unique_ptr<ViewServer> server_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

http::response<http::string_body> request(int port, http::verb verb, const std::string& target,
                                          const std::string& host = "127.0.0.1",
                                          const std::string& origin = "") {
    net::io_context ioc;
    beast::tcp_stream stream(ioc);
    stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)));
    http::request<http::string_body> req{verb, target, 11};
    req.set(http::field::host, host);
    if (!origin.empty()) req.set(http::field::origin, origin);
    http::write(stream, req);
    beast::flat_buffer buffer;
    http::response<http::string_body> res;
    http::read(stream, buffer, res);
    beast::error_code ec;
    stream.socket().shutdown(tcp::socket::shutdown_both, ec);
    return res;
}

/// A WebSocket client of /api/ws.
class Viewer {
public:
    explicit Viewer(int port) : port_(port), ws_(ioc_) {
        beast::get_lowest_layer(ws_).connect(
            tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)));
        ws_.handshake("127.0.0.1", "/api/ws");
    }
    void send(const std::string& text) {
        ws_.text(true);
        ws_.write(net::buffer(text));
    }
    /// The next message: its text (empty for a binary one) and its bytes.
    std::pair<bool, std::string> next() {
        beast::flat_buffer b;
        ws_.read(b);
        return {ws_.got_text(), beast::buffers_to_string(b.data())};
    }
    nlohmann::json nextText() {
        auto [text, data] = next();
        EXPECT_TRUE(text);
        return nlohmann::json::parse(data);
    }
    /// Reads until the final update of `seq`, checking each update's binary part.
    nlohmann::json untilFinal(std::uint32_t seq) {
        for (;;) {
            const nlohmann::json m = nextText();
            if (m["type"] != "update") continue;
            auto [text, bin] = next();
            EXPECT_FALSE(text);
            EXPECT_GE(bin.size(), 16u);
            if (m.contains("body")) {
                // A whole cache: the WebSocket carries the header alone, the values come by HTTP.
                EXPECT_EQ(bin.size(), 16u);
                const auto res = request(port_, http::verb::get, m["body"].get<std::string>());
                EXPECT_EQ(res.result(), http::status::ok);
                bin = res.body();
                ++bodies;
            }
            std::uint32_t header[4];
            std::memcpy(header, bin.data(), 16);
            EXPECT_EQ(header[0], 0x564d5350u);
            EXPECT_EQ(header[1], m["seq"].get<std::uint32_t>());
            EXPECT_EQ(bin.size(), 16 + size_t(header[3]) * 3 * 2);
            if (m["phase"] == "final" && m["seq"] == seq) return m;
        }
    }
    websocket::stream<beast::tcp_stream>& stream() { return ws_; }
    int bodies = 0;  ///< updates whose values came by HTTP

private:
    int port_;
    net::io_context ioc_;
    websocket::stream<beast::tcp_stream> ws_;
};

std::string setMessage(std::uint32_t seq, double azimuth, double elevation) {
    return nlohmann::json{
        {"type", "set"}, {"seq", seq}, {"controls", {{"azimuth", azimuth}, {"elevation", elevation}}}}
        .dump();
}

class ViewServerTest : public ::testing::Test {
protected:
    void SetUp() override {
        if (!smallVolume().scene) PMSC_MISSING_DATA("assimp-testmodels not installed (WusonOBJ.obj)");
    }
};

TEST_F(ViewServerTest, ServesThePageTheSceneAndItsGeometryAndNothingElse) {
    Running server(smallVolume().model);
    const Index n = smallVolume().scene->pointCount();
    auto scene = request(server.port(), http::verb::get, "/api/scene");
    EXPECT_EQ(scene.result(), http::status::ok);
    const auto j = nlohmann::json::parse(scene.body());
    EXPECT_EQ(j["kind"], "volume");
    EXPECT_EQ(j["points"], n);
    EXPECT_EQ(j["controls"].size(), 3u);
    EXPECT_EQ(j["model"]["keys"], smallVolume().model.keyCount());
    const auto dims = j["grid"]["dims"];
    EXPECT_GE(dims[0].get<long long>() * dims[1].get<long long>() * dims[2].get<long long>(), n);
    EXPECT_EQ(request(server.port(), http::verb::get, "/api/geometry").body().size(), size_t(n) * 8);
    EXPECT_NE(request(server.port(), http::verb::get, "/").body().find("pmsc view"), std::string::npos);
    auto js = request(server.port(), http::verb::get, "/app/main.js?v=1");
    EXPECT_EQ(js.result(), http::status::ok);
    EXPECT_EQ(js[http::field::content_type], "text/javascript; charset=utf-8");
    EXPECT_EQ(request(server.port(), http::verb::get, "/app/../index.html").result(),
              http::status::not_found);
    EXPECT_EQ(request(server.port(), http::verb::get, "/etc/passwd").result(), http::status::not_found);
    EXPECT_EQ(request(server.port(), http::verb::get, "/app/missing.js").result(), http::status::not_found);
    EXPECT_EQ(request(server.port(), http::verb::post, "/api/scene").result(),
              http::status::method_not_allowed);
}

TEST_F(ViewServerTest, ARelightArrivesAsTextThenItsHalfFloats) {
    Running server(smallVolume().model);
    Viewer v(server.port());
    EXPECT_EQ(v.nextText()["type"], "hello");
    v.send(setMessage(1, 90, 40));
    const auto last = v.untilFinal(1);
    EXPECT_TRUE(last["converged"].get<bool>());
    EXPECT_EQ(last["checksum"].get<std::string>().size(), 16u);
}

TEST_F(ViewServerTest, AWholeCacheComesByHttpAndIsServedOnce) {
    Model missing = smallVolume().model;
    missing.epsMin = missing.epsMax = 0;  // an estimate (the whole cache), then branches
    Running server(missing, 1024);        // every whole cache by HTTP, the branches too
    Viewer v(server.port());
    v.nextText();
    v.send(setMessage(1, 30, 20));
    EXPECT_EQ(v.untilFinal(1)["state"], "miss");
    EXPECT_GE(v.bodies, 2) << "the estimate and the branches came by HTTP";
    EXPECT_EQ(request(server.port(), http::verb::get, "/api/body/1").result(), http::status::not_found)
        << "a body is served once";
    EXPECT_EQ(request(server.port(), http::verb::get, "/api/body/x").result(), http::status::not_found);
}

TEST_F(ViewServerTest, AWaitingBodyRequestGetsTheNextWholeCacheWithItsAddress) {
    Running server(smallVolume().model, 1024);  // every whole cache by HTTP
    Viewer v(server.port());
    v.nextText();
    // Asked for before the frame exists: answered when the server makes the body (or at once, had
    // the body been made first: the same answer).
    auto waiting = std::async(std::launch::async, [port = server.port()] {
        return request(port, http::verb::get, "/api/body/next");
    });
    v.send(setMessage(1, 30, 20));
    nlohmann::json m;
    do m = v.nextText();
    while (m["type"] != "update" || !m.contains("body"));
    auto [text, header] = v.next();
    EXPECT_FALSE(text);
    EXPECT_EQ(header.size(), 16u) << "the WebSocket carries the header alone";
    const auto res = waiting.get();
    ASSERT_EQ(res.result(), http::status::ok);
    EXPECT_EQ(res["X-Pmsc-Body"], m["body"].get<std::string>());
    std::uint32_t h[4];
    ASSERT_GE(res.body().size(), 16u);
    std::memcpy(h, res.body().data(), 16);
    EXPECT_EQ(h[0], 0x564d5350u);
    EXPECT_EQ(h[1], 1u);
    EXPECT_EQ(res.body().size(), 16 + size_t(h[3]) * 3 * 2);
    EXPECT_EQ(request(server.port(), http::verb::get, m["body"].get<std::string>()).result(),
              http::status::not_found)
        << "served once: to the waiting request";
}

TEST_F(ViewServerTest, AMalformedMessageGetsAnErrorAndTheConnectionStaysUsable) {
    Running server(smallVolume().model);
    Viewer v(server.port());
    v.nextText();
    v.send("{\"type\":\"set\",\"seq\":");
    const auto err = v.nextText();
    EXPECT_EQ(err["type"], "error");
    EXPECT_NE(err["message"].get<std::string>().find("not JSON"), std::string::npos);
    v.stream().binary(true);
    v.stream().write(net::buffer(std::string("\x01\x02", 2)));
    EXPECT_NE(v.nextText()["message"].get<std::string>().find("binary messages"), std::string::npos);
    v.send(setMessage(2, 10, 10));
    EXPECT_TRUE(v.untilFinal(2)["converged"].get<bool>());
}

TEST_F(ViewServerTest, ASecondViewerIsToldAndClosedWhileTheFirstGoesOn) {
    Running server(smallVolume().model);
    Viewer first(server.port());
    first.nextText();
    Viewer second(server.port());
    const auto err = second.nextText();
    EXPECT_EQ(err["type"], "error");
    EXPECT_NE(err["message"].get<std::string>().find("one at a time"), std::string::npos);
    beast::flat_buffer b;
    beast::error_code ec;
    second.stream().read(b, ec);
    EXPECT_EQ(ec, websocket::error::closed);
    first.send(setMessage(1, 45, 45));
    EXPECT_TRUE(first.untilFinal(1)["converged"].get<bool>());
}

TEST_F(ViewServerTest, AViewerThatLeavesMidFrameFreesTheServerForTheNext) {
    Model missing = smallVolume().model;
    missing.epsMin = missing.epsMax = 0;  // every frame fails through: the client leaves mid-way
    Running server(missing);
    {
        Viewer v(server.port());
        v.nextText();
        v.send(setMessage(1, 30, 20));
        EXPECT_EQ(v.nextText()["phase"], "estimate");
        beast::get_lowest_layer(v.stream()).socket().close();  // no close handshake
    }
    // The server lets the first viewer go when it notices; a new one is served.
    for (int attempt = 0;; ++attempt) {
        Viewer v(server.port());
        const auto hello = v.nextText();
        if (hello["type"] == "hello") {
            v.send(setMessage(2, 60, 20));
            EXPECT_EQ(v.untilFinal(2)["state"], "miss");
            break;
        }
        ASSERT_LT(attempt, 50) << "the server still holds the viewer that left";
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
}

TEST(ViewServerOrigin, OnlyNamesOfThisMachineAndItsOwnPageAreAnswered) {
    EXPECT_TRUE(hostAllowed("127.0.0.1:8080", "127.0.0.1", {}));
    EXPECT_TRUE(hostAllowed("localhost:8080", "127.0.0.1", {}));
    EXPECT_TRUE(hostAllowed("LocalHost", "127.0.0.1", {}));
    EXPECT_TRUE(hostAllowed("[::1]:8080", "127.0.0.1", {}));
    EXPECT_TRUE(hostAllowed("127.1.2.3", "127.0.0.1", {}));
    EXPECT_TRUE(hostAllowed("10.1.2.3:8080", "10.1.2.3", {}));
    EXPECT_TRUE(hostAllowed("0.0.0.0:8080", "0.0.0.0", {}));
    EXPECT_TRUE(hostAllowed("render7:8080", "0.0.0.0", {"render7"}));
    EXPECT_FALSE(hostAllowed("evil.example:8080", "127.0.0.1", {}));  // a DNS-rebinding name
    EXPECT_FALSE(hostAllowed("render7:8080", "0.0.0.0", {}));
    EXPECT_FALSE(hostAllowed("10.1.2.3:8080", "0.0.0.0", {}));
    EXPECT_FALSE(hostAllowed("", "127.0.0.1", {}));
    EXPECT_FALSE(hostAllowed("[::1", "127.0.0.1", {}));
    EXPECT_FALSE(hostAllowed("127.0.0.1:80:80", "127.0.0.1", {}));
    EXPECT_TRUE(sameOrigin("", "127.0.0.1:8080"));
    EXPECT_TRUE(sameOrigin("http://127.0.0.1:8080", "127.0.0.1:8080"));
    EXPECT_FALSE(sameOrigin("http://evil.example", "127.0.0.1:8080"));
    EXPECT_FALSE(sameOrigin("http://127.0.0.1:9999", "127.0.0.1:8080"));
    EXPECT_FALSE(sameOrigin("null", "127.0.0.1:8080"));
    // --allow-origin: a page the user serves elsewhere, exactly (case aside), nothing else.
    EXPECT_TRUE(sameOrigin("http://Notebook:8888", "127.0.0.1:8080", {"http://notebook:8888"}));
    EXPECT_FALSE(sameOrigin("http://notebook:8889", "127.0.0.1:8080", {"http://notebook:8888"}));
    EXPECT_FALSE(sameOrigin("http://evil.example", "127.0.0.1:8080", {"http://notebook:8888"}));
}

TEST_F(ViewServerTest, AnAllowedOriginsPageIsAnsweredAndOnlyIt) {
    const Running server(smallVolume().model, 256 * 1024, {"http://notebook:8888"});
    const int port = server.port();
    const std::string self = "127.0.0.1:" + std::to_string(port);
    EXPECT_EQ(request(port, http::verb::get, "/api/scene", self, "http://notebook:8888").result(),
              http::status::ok);
    const auto other = request(port, http::verb::get, "/api/scene", self, "http://notebook:9999");
    EXPECT_EQ(other.result(), http::status::forbidden);
    EXPECT_NE(other.body().find("--allow-origin"), std::string::npos) << other.body();
}

TEST_F(ViewServerTest, AnotherSitesPageOrHostNameGets403AndNoSession) {
    const Running server(smallVolume().model);
    const int port = server.port();
    const std::string self = "127.0.0.1:" + std::to_string(port);
    EXPECT_EQ(request(port, http::verb::get, "/api/scene", self, "http://" + self).result(),
              http::status::ok);
    // DNS rebinding: a name of the attacker's pointing at 127.0.0.1.
    const auto rebound = request(port, http::verb::get, "/api/scene", "evil.example:" + std::to_string(port));
    EXPECT_EQ(rebound.result(), http::status::forbidden);
    EXPECT_NE(rebound.body().find("evil.example"), std::string::npos);
    EXPECT_EQ(request(port, http::verb::get, "/api/scene", self, "http://evil.example").result(),
              http::status::forbidden);
    // A WebSocket from another site's page is refused at the handshake; the server's own page is not.
    {
        net::io_context ioc;
        websocket::stream<beast::tcp_stream> ws(ioc);
        beast::get_lowest_layer(ws).connect(
            tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)));
        ws.set_option(websocket::stream_base::decorator(
            [](websocket::request_type& req) { req.set(http::field::origin, "http://evil.example"); }));
        websocket::response_type res;
        beast::error_code ec;
        ws.handshake(res, self, "/api/ws", ec);
        EXPECT_EQ(ec, websocket::error::upgrade_declined);
    }
    Viewer v(port);
    EXPECT_EQ(v.nextText()["type"], "hello");
}

TEST_F(ViewServerTest, AnAddressInUseOrAMissingPageIsOneLine) {
    Running server(smallVolume().model);
    ViewServerOptions o;
    o.port = server.port();
    o.webRoot = smallVolume().dir + "/web";
    try {
        ViewServer again(smallVolume().model, *smallVolume().scene, o);
        FAIL() << "bound a port in use";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("cannot listen on 127.0.0.1:" + std::to_string(o.port)),
                  std::string::npos)
            << e.what();
    }
    o.port = 0;
    o.webRoot = smallVolume().dir + "/nowhere";
    try {
        ViewServer none(smallVolume().model, *smallVolume().scene, o);
        FAIL() << "served without a page";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no index.html"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace pmsc::viewer
