"""A stand-in child process for launcher tests: ignores its arguments and sleeps."""

import time

if __name__ == "__main__":
    time.sleep(60)
