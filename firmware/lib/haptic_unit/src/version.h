// The firmware's version, sent in the HELLO reply (`OK <role> <version>`).
#pragma once

#define HAPTIC_UNIT_VERSION "1.1.0"
#define HAPTIC_UNIT_PROTOCOL 1
