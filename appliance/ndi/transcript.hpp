#pragma once
// Session transcripts: what went over a serial link, in a line-oriented text format that
// people can read and the bench simulator can replay. Format (docs/appliance.md):
//
//   # arnav-ndi transcript 1          <- required first line
//   # any other line starting with # is a comment; empty lines are ignored
//   <t_us> cmd <bytes>                host -> device bytes (a whole command, CR included)
//   <t_us> reply <bytes>              device -> host bytes (a whole reply, CR included)
//   <t_us> baud <rate>                host changed its serial rate
//   <t_us> break <duration_ms>        host sent a serial break
//   <t_us> note <text>                free text (escaped like bytes)
//
// t_us: microseconds since the start of the recording (non-negative integer, never
// decreasing). <bytes>: everything after the single space that follows the kind, with
// escapes: \\ backslash, \r CR, \n LF, \t TAB, \xHH any byte; printable ASCII (0x20-0x7E)
// is written as itself except a trailing space, which is written \x20.
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace arnav::ndi {

class TranscriptError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct TranscriptRecord {
  enum class Kind : std::uint8_t { Command, Reply, Baud, Break, Note };
  std::int64_t t_us = 0;
  Kind kind = Kind::Note;
  std::string bytes;   // Command, Reply: raw bytes; Note: text
  std::int64_t value = 0;  // Baud: rate; Break: duration in ms
  int line = 0;        // source line when read from text (1-based), 0 otherwise
};

std::string_view to_string(TranscriptRecord::Kind kind);

inline constexpr std::string_view kTranscriptHeader = "# arnav-ndi transcript 1";

std::string escape_bytes(std::string_view bytes);
// nullopt on a malformed escape.
std::optional<std::string> unescape_bytes(std::string_view text);

// Throws TranscriptError("<source>:<line>: <what is wrong>").
std::vector<TranscriptRecord> read_transcript(std::istream& in, std::string_view source = "transcript");
std::vector<TranscriptRecord> read_transcript_file(const std::filesystem::path& path);

std::string format_record(const TranscriptRecord& record);  // one line, no newline
void write_transcript(std::ostream& out, const std::vector<TranscriptRecord>& records);

// Converts an IGSTK serial log (lines "<epoch> : (INFO) N. command[len] ..." and
// "... receive[len] ..."; \xNN escapes) into transcript records; times become relative
// to the first logged line. Throws TranscriptError naming the line on a length mismatch.
std::vector<TranscriptRecord> import_igstk_log(std::istream& in, std::string_view source = "igstk log");

}  // namespace arnav::ndi
