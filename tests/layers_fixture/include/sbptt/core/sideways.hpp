#pragma once
// A fixture for the layer check: a core header that includes a folder beside nn.
#include <sbptt/optim/adam.hpp>
