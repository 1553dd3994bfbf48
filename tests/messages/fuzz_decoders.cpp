// SPDX-License-Identifier: Apache-2.0
// libFuzzer target for everything that decodes bytes from the network or the disk: the checked
// LCM decoders of every plumb type, envelope verification, the fragment codec and the fragment
// assembler. The first input byte picks the decoder. Any crash, sanitizer report, leak or
// out-of-memory is a bug: malformed input must come back as a Status.
//
// Built only when clang++ is found (tests/messages/CMakeLists.txt) and run by ctest for a bounded
// time: fuzz_decoders -max_total_time=20 -rss_limit_mb=1024.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/conversions.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/wire.hpp"

namespace {

using namespace plumb::messages;

class NullTransport final : public Transport {
  public:
    plumb::Status publish(const std::string&, std::span<const uint8_t>) override {
        return plumb::Status::ok();
    }
    plumb::Status subscribe(const std::string&, Handler) override { return plumb::Status::ok(); }
};

template <typename T>
void decodeAndConvert(std::span<const uint8_t> bytes) {
    auto msg = decodeMessage<T>(bytes);
    if constexpr (requires(const T& m) { fromMessage(m); }) {
        if (msg.isOk()) (void)fromMessage(*msg);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (size < 1) return 0;
    const std::span<const uint8_t> bytes(data + 1, size - 1);
    switch (data[0] % 16) {
        case 0:
            decodeAndConvert<plumb::device_status_t>(bytes);
            break;
        case 1:
            decodeAndConvert<plumb::fragment_header_t>(bytes);
            break;
        case 2:
            decodeAndConvert<plumb::fragment_chunk_t>(bytes);
            break;
        case 3:
            decodeAndConvert<plumb::fragment_ack_t>(bytes);
            break;
        case 4:
            decodeAndConvert<plumb::retransmit_request_t>(bytes);
            break;
        case 5:
            decodeAndConvert<plumb::camera_info_t>(bytes);
            break;
        case 6:
            decodeAndConvert<plumb::depth_frame_t>(bytes);
            break;
        case 7:
            decodeAndConvert<plumb::config_snapshot_t>(bytes);
            break;
        case 8:
            decodeAndConvert<plumb::envelope_t>(bytes);
            break;
        case 9:
            (void)decodeFragment(bytes);
            break;
        case 12:
            decodeAndConvert<plumb::depth_frame2_t>(bytes);
            break;
        case 13:
            (void)decodeRawFrame(bytes);
            break;
        case 15:
            decodeAndConvert<plumb::depth_frame3_t>(bytes);
            break;
        case 14: {
            // The sender's handling of "cannot store" answers (checked values, no state kept).
            NullTransport net;
            FragmentSenderConfig config;
            FragmentSender sender(config, net);
            (void)sender.onMessage(kChannelFragmentBackoff, bytes, 0.0);
            break;
        }
        case 10: {
            static const std::vector<uint8_t> key(32, 0x42);
            ReplayGuard guard(64, 4);
            AuthStats stats;
            (void)openMessage(kChannelFragmentChunk, bytes, key, 1, guard, stats);
            break;
        }
        default: {
            // A stream of messages to the assembler: length-prefixed (u16) pieces, alternating
            // channels, with tight limits so absurd sizes are exercised without huge buffers.
            NullTransport net;
            FragmentAssemblerConfig config;
            config.max_fragment_bytes = 1 << 20;
            config.max_buffered_bytes = 1 << 20;
            FragmentAssembler assembler(config, net);
            size_t pos = 0;
            double now = 0.0;
            bool header = true;
            while (pos + 2 <= bytes.size()) {
                const size_t n =
                    std::min<size_t>(bytes[pos] | (bytes[pos + 1] << 8), bytes.size() - pos - 2);
                (void)assembler.onMessage(header ? kChannelFragmentHeader : kChannelFragmentChunk,
                                          bytes.subspan(pos + 2, n), now);
                assembler.poll(now += 0.3);
                (void)assembler.takeCompleted();
                header = !header;
                pos += 2 + n;
            }
            break;
        }
    }
    return 0;
}
