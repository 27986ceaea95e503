// refine_rotation is defined inline in rotation_extraction.hpp (hot loop of XPBD); this
// translation unit checks that the header compiles on its own.
#include "host/sim/rotation_extraction.hpp"
