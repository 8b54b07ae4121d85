// The random number source appendix A.2 declares but does not define.
#include <random>

float randomFloat()
{
    static std::mt19937 engine(2019);
    static std::uniform_real_distribution<float> uniform(0.f, 0.99999994f);
    return uniform(engine);
}
