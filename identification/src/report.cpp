#include "cpm/identification/diagnose.hpp"
namespace cpm::ident {}
