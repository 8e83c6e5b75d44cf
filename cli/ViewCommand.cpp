// `pmsc view`: interactive relighting in a browser (viewer/ViewServer.h, docs/viewer.md).
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "viewer/RelightScene.h"
#include "viewer/ViewServer.h"

#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

namespace pmsc::cli {

namespace {

struct ViewArgs {
    std::string model, scene, sceneFile, bind = "127.0.0.1", web;
    int port = 8080;
    int threads = 0;
    std::vector<std::string> allowedHosts, allowedOrigins;
};

std::optional<ViewArgs> parseViewArgs(const std::vector<std::string>& args) {
    ViewArgs a;
    ArgParser parser("view", "--model M.pmsc (--scene SPEC | --scene-file FILE) [--port P] [--bind ADDR]",
                     "Serves a page that relights a scene interactively: drag the light, and the soft\n"
                     "cache answers from the key points at once; where it blends or misses, the full\n"
                     "calculation streams in, branch by branch, until the picture converges. Prints the\n"
                     "address, then serves until interrupted (Ctrl-C). One viewer at a time.\n"
                     "SPEC: volume:FILE.vdb[:grid=NAME][:samples=S] or cornell[:points=N,samples=S];\n"
                     "`pmsc demo volume|cornell --out DIR` writes DIR/model.pmsc and DIR/scene.txt.");
    parser.option("--model", "M.pmsc", "a model trained on the scene's points", a.model, true);
    parser.option("--scene", "SPEC", "the scene (as the volume/cornell evaluators take it)", a.scene);
    parser.option("--scene-file", "FILE", "a file holding the SPEC (a demo's scene.txt)", a.sceneFile);
    parser.option("--port", "P", "TCP port (default 8080; 0: any free port)",
                  [&](const std::string& v) { a.port = int(parseIndex("--port", v, 0, 65535)); });
    parser.option("--bind", "ADDR", "address to listen on (default 127.0.0.1: this machine only)", a.bind);
    parser.option("--allow-host", "NAME",
                  "a host name the page may be reached by besides localhost and the bound address "
                  "(repeatable; requests naming any other host, and WebSockets from other sites' "
                  "pages, get 403)",
                  [&](const std::string& v) { a.allowedHosts.push_back(v); });
    parser.repeatable("--allow-host");
    parser.option("--allow-origin", "ORIGIN",
                  "a page's origin (scheme://host[:port], e.g. http://notebook:8888) that may use the "
                  "API and drive the session besides this server's own page (repeatable)",
                  [&](const std::string& v) {
                      if (v.find("://") == std::string::npos || v.back() == '/')
                          throw UsageError("--allow-origin: '" + v +
                                           "' is not an origin (scheme://host[:port], no path)");
                      a.allowedOrigins.push_back(v);
                  });
    parser.repeatable("--allow-origin");
    parser.option("--web", "DIR", "the page's folder (default: the build's web/viewer)", a.web);
    parser.option("--threads", "T", "engine worker threads (default: every core)",
                  [&](const std::string& v) { a.threads = int(parseIndex("--threads", v, 0, 4096)); });
    if (!parser.parse(args)) return std::nullopt;
    if (a.scene.empty() == a.sceneFile.empty()) parser.fail("give exactly one of --scene and --scene-file");
    if (!a.sceneFile.empty()) {
        std::ifstream in(a.sceneFile);
        if (!in) throw InputError("view: cannot read the scene file '" + a.sceneFile + "'");
        std::getline(in, a.scene);
        if (a.scene.empty()) throw InputError("view: the scene file '" + a.sceneFile + "' is empty");
    }
    if (a.web.empty()) a.web = viewer::defaultWebRoot();
    return a;
}

}  // namespace

int runView(const std::vector<std::string>& args) {
    const std::optional<ViewArgs> a = parseViewArgs(args);
    if (!a) return kExitOk;
    installInterruptHandler();
    const Model model = readModel(a->model);
    const std::unique_ptr<viewer::RelightScene> scene = viewer::makeRelightScene(a->scene);
    viewer::ViewServerOptions o;
    o.bind = a->bind;
    o.port = a->port;
    o.webRoot = a->web;
    o.threads = a->threads;
    o.allowedHosts = a->allowedHosts;
    o.allowedOrigins = a->allowedOrigins;
    viewer::ViewServer server(model, *scene, o);
    const std::string host = a->bind.find(':') != std::string::npos ? "[" + a->bind + "]" : a->bind;
    std::cout << "pmsc view: http://" << host << ":" << server.port() << "/" << std::endl;
    server.run(interruptFlag());
    std::cerr << "pmsc view: stopped\n";
    return kExitOk;
}

}  // namespace pmsc::cli
