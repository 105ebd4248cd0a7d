from augnet.cli import main

main()
