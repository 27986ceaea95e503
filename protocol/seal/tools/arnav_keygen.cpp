// arnav-keygen FILE: makes a bus session key (32 random bytes, mode 0600, never
// overwriting) for the sealed bus (docs/protocol.md, "Sealed bus"). Prints the key id.
// Exit 0 made, 2 cannot make it (the message names the file).
#include <CLI/CLI.hpp>

#include <iostream>

#include "protocol/guarded_main.hpp"
#include "protocol/seal/key.hpp"

static int main_body(int argc, char** argv) {
  CLI::App cli{"arnav-keygen: make a session key for the sealed LCM bus (docs/protocol.md)"};
  std::string path;
  cli.add_option("file", path, "key file to create (mode 0600; an existing file is never overwritten)")->required();
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e) == 0 ? 0 : 2;
  }
  try {
    const std::uint32_t id = arnav::seal::write_new_key(path);
    std::cout << "arnav-keygen: wrote " << path << " (32 bytes, mode 0600), key id " << arnav::seal::key_id_hex(id)
              << ". Copy it to the appliance and the host with install -m 600; never to a shared folder.\n";
    return 0;
  } catch (const arnav::seal::KeyError& e) {
    std::cerr << "arnav-keygen: " << e.what() << "\n";
    return 2;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-keygen", [&] { return main_body(argc, argv); });
}
