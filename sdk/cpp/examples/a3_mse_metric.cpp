// Thesis appendix A.3, "IQA Metric Example": mean squared error with
// OpenCV, as printed, with only what the PDF extraction lost restored:
// braces, three semicolons printed as colons, and the empty reference
// string whose line survived only as its comment.
#include <fbksd/iqa/iqa.h>
#include <opencv2/core/core.hpp>
#include <opencv2/highgui/highgui.hpp>
#include <opencv2/imgproc/imgproc.hpp>

using namespace cv;

static float computeMSE(const Mat& img1, const Mat& img2)
{
    Mat s1;
    absdiff(img1, img2, s1);
    s1 = s1.mul(s1);
    Scalar s = sum(s1);
    double sse = s.val[0] + s.val[1] + s.val[2];

    double mse = sse / (double)(img1.channels() * img1.total());
    return mse;
}

int main(int argc, char* argv[])
{
    // STEP 1: Create an instance of fbksd::IQA, passing the required information.
    fbksd::IQA iqa(argc, argv,                              // argc, argv from main()
                   "My-MSE",                                // Metric's acronym
                   "My Simple Mean squared error metric",   // Metric's full name
                   "",                                      // Reference (optional)
                   true,                                    // lowerIsBetter flag
                   false);                                  // hasErrorMap flag
    fbksd::Img ref;
    fbksd::Img test;
    // STEP 2: Load the input images.
    iqa.loadInputImages(ref, test);
    // STEP 3: Compute the IQA value comparing the two images.
    Mat refMat(ref.height(), ref.width(), CV_32FC3, ref.data());
    Mat testMat(ref.height(), ref.width(), CV_32FC3, test.data());
    float error = computeMSE(refMat, testMat);
    // STEP 4: Report the value (and the error map, if supported).
    iqa.report(error);
    return 0;
}
