// libFuzzer target: the .pmsc model reader (pmsc/ModelIO, ModelSections, ByteIO), format
// versions 1 and 2 (tagged sections). Every input is decoded twice: as it is (magic, version,
// sizes, checksum) and with its checksum made right, so the fuzzer reaches the arrays, the
// model's own validation and every section codec instead of stopping at the checksum. The
// contract: decodeModel() returns a valid model or throws pmsc::InputError, and a model it
// returns can be written and read back.
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

using namespace pmsc;

namespace {

void decodeAndRoundTrip(std::string_view bytes) {
    Model model;
    try {
        model = decodeModel(bytes, "fuzz.pmsc");
    } catch (const InputError&) {
        return;
    }
    // What the reader accepts, the writer must write (validate() passes) and the reader re-read.
    const std::string again = encodeModel(model);
    const Model back = decodeModel(again, "fuzz-again.pmsc");
    if (back.points != model.points || back.keyPoints != model.keyPoints) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view raw(reinterpret_cast<const char*>(data), size);
    decodeAndRoundTrip(raw);
    if (size >= kModelHeaderBytes + 8) {
        std::string fixed(raw);
        const std::uint64_t sum = fnv1a64(fixed.data(), fixed.size() - 8);
        std::memcpy(fixed.data() + fixed.size() - 8, &sum, 8);
        decodeAndRoundTrip(fixed);
    }
    return 0;
}
